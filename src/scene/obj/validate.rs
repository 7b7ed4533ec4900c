//! Line checks tobj does not make: the first malformed OBJ or MTL line, so an error can
//! name it (tobj skips or misreads such lines silently).

pub(super) fn floats(words: &[&str]) -> usize {
    words
        .iter()
        .take_while(|w| w.parse::<f64>().is_ok())
        .count()
}

/// What is wrong with the coordinates tobj keeps of a line (`kept`, in f64 as it reads them):
/// the first that is not a finite `f32` (NaN, infinity, beyond `f32`'s range), which the
/// renderer cannot place. Named with its line here, since tobj reads such values silently
/// and the loader meets them without a line.
fn non_finite_coordinate(kept: &[f64]) -> Option<String> {
    kept.iter()
        .find(|&&x| !(x as f32).is_finite())
        .map(|x| format!("a coordinate is {x:e}, not a finite 32-bit number"))
}

/// The first `N` numbers of `words`, which the caller has checked parse (`floats`).
fn leading<const N: usize>(words: &[&str]) -> [f64; N] {
    std::array::from_fn(|i| words[i].parse().unwrap_or(f64::NAN))
}

/// What tobj keeps of a valid `v` line's numbers: `x y z`, divided by `w` when there is
/// one (vertex colours are not read).
fn kept_position(args: &[&str]) -> [f64; 3] {
    let xyz = leading::<3>(args);
    match args {
        [_, _, _, w] => xyz.map(|c| c / w.parse::<f64>().unwrap_or(f64::NAN)),
        _ => xyz,
    }
}

/// The first line (1-based) of an MTL text the parser would reject, and why.
pub(super) fn first_bad_mtl_line(text: &str) -> Option<(usize, String)> {
    for (i, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, args)) = words.split_first() else {
            continue;
        };
        let problem = match key {
            "Ka" | "Kd" | "Ks" | "Ke" if floats(args) < 3 => Some("expected three numbers"),
            "Ns" | "Ni" | "d" if floats(args) < 1 => Some("expected a number"),
            "illum" if args.first().and_then(|a| a.parse::<u8>().ok()).is_none() => {
                Some("expected an illumination model number")
            }
            "newmtl" | "map_Ka" | "map_Kd" | "map_Ks" | "map_Bump" | "map_bump" | "map_Ns"
            | "map_ns" | "map_NS" | "bump" | "map_d"
                if args.is_empty() =>
            {
                Some("expected a name")
            }
            _ => None,
        };
        if let Some(problem) = problem {
            return Some((i + 1, format!("{key}: {problem}")));
        }
    }
    None
}

/// Resolves a 1-based or negative (relative) OBJ index against `count` elements so far.
pub(super) fn index_ok(word: &str, count: usize) -> bool {
    match word.parse::<i64>() {
        Ok(i) if i > 0 => (i as usize) <= count,
        Ok(i) if i < 0 => i.unsigned_abs() as usize <= count,
        _ => false,
    }
}

/// The first line (1-based) of an OBJ text the parser would reject, and why.
pub(super) fn first_bad_obj_line(text: &str) -> Option<(usize, String)> {
    let (mut v, mut vt, mut vn) = (0usize, 0usize, 0usize);
    for (i, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&key, args)) = words.split_first() else {
            continue;
        };
        let problem: Option<String> = match key {
            "v" => {
                let n = floats(args);
                if n < 3 || args.len() != n || !matches!(n, 3 | 4 | 6) {
                    Some("expected x y z [w | r g b]".into())
                } else if n == 4 && args[3].parse::<f64>() == Ok(0.0) {
                    Some("w is zero".into())
                } else {
                    let problem = non_finite_coordinate(&kept_position(args));
                    v += usize::from(problem.is_none());
                    problem
                }
            }
            "vt" => {
                if floats(args) < 2 {
                    Some("expected u v".into())
                } else {
                    let problem = non_finite_coordinate(&leading::<2>(args));
                    vt += usize::from(problem.is_none());
                    problem
                }
            }
            "vn" => {
                if floats(args) < 3 {
                    Some("expected x y z".into())
                } else {
                    let problem = non_finite_coordinate(&leading::<3>(args));
                    vn += usize::from(problem.is_none());
                    problem
                }
            }
            "f" => {
                if args.len() < 3 {
                    Some("a face needs at least three vertices".into())
                } else {
                    args.iter().find_map(|corner| {
                        let parts: Vec<&str> = corner.split('/').collect();
                        let ok = match parts.as_slice() {
                            [a] => index_ok(a, v),
                            [a, b] => index_ok(a, v) && index_ok(b, vt),
                            [a, "", c] => index_ok(a, v) && index_ok(c, vn),
                            [a, b, c] => index_ok(a, v) && index_ok(b, vt) && index_ok(c, vn),
                            _ => false,
                        };
                        (!ok).then(|| {
                            format!("face corner {corner}: bad or out-of-range index ({v} v, {vt} vt, {vn} vn so far)")
                        })
                    })
                }
            }
            "l" => Some("line elements are not supported".into()),
            "usemtl" | "mtllib" if args.is_empty() => Some(format!("{key} needs a name")),
            _ => None,
        };
        if let Some(problem) = problem {
            return Some((i + 1, format!("{key}: {problem}")));
        }
    }
    None
}
