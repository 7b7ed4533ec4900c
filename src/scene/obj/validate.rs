//! Line checks tobj does not make: the first malformed OBJ or MTL line, so an error can
//! name it (tobj skips or misreads such lines silently).

pub(super) fn floats(words: &[&str]) -> usize {
    words
        .iter()
        .take_while(|w| w.parse::<f64>().is_ok())
        .count()
}

/// The first of `values` (as tobj keeps them, in f64) that is not a finite `f32` (NaN,
/// infinity, or beyond `f32`'s range), which the renderer cannot place: named with its line
/// here, since tobj reads such values silently and the loader meets them without a line.
fn non_finite(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    values.into_iter().find(|&x| !(x as f32).is_finite())
}

/// The numbers of `words` (all of which parse).
fn numbers(words: &[&str]) -> Vec<f64> {
    words.iter().filter_map(|w| w.parse::<f64>().ok()).collect()
}

/// What tobj keeps of a valid `v` line's numbers: `x y z`, divided by `w` when there is
/// one (vertex colours are not read).
fn kept_position(args: &[&str]) -> Vec<f64> {
    let n = numbers(args);
    match n.as_slice() {
        [x, y, z, w] => vec![x / w, y / w, z / w],
        _ => n[..3].to_vec(),
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
                } else if let Some(x) = non_finite(kept_position(args)) {
                    Some(format!("a coordinate is {x:e}, not a finite 32-bit number"))
                } else {
                    v += 1;
                    None
                }
            }
            "vt" => {
                if floats(args) < 2 {
                    Some("expected u v".into())
                } else if let Some(x) = non_finite(numbers(&args[..2])) {
                    Some(format!("a coordinate is {x:e}, not a finite 32-bit number"))
                } else {
                    vt += 1;
                    None
                }
            }
            "vn" => {
                if floats(args) < 3 {
                    Some("expected x y z".into())
                } else if let Some(x) = non_finite(numbers(&args[..3])) {
                    Some(format!("a coordinate is {x:e}, not a finite 32-bit number"))
                } else {
                    vn += 1;
                    None
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
