//! The layering rules of ARCHITECTURE.md, checked on the source files: which top-level
//! modules of `src/` may reach which, through their own imports or through the modules they
//! import (every rule is checked on the transitive closure), and that nothing below the
//! command line prints.
//!
//! The graph has one node per top-level module of `src/` (a folder or a file) and an edge
//! wherever the module's library code names `crate::<other>` (`crate::scene::X`, a grouped
//! `use crate::{geometry, scene::X}`, a `$crate::` path in a macro, a doc link). Test code
//! (`#[cfg(test)]` items and the files of `#[cfg(test)] mod x;`) is left out: a test may
//! build its fixtures from anywhere. A rule that fails names the path through the graph
//! and, for each step, the file and line that names the next module.

#[path = "common/files.rs"]
mod files;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

/// Which modules a rule is about.
#[derive(Debug, Clone, Copy)]
enum Modules {
    Only(&'static [&'static str]),
    /// Every top-level module but these.
    AllBut(&'static [&'static str]),
}

/// What each of `modules` must not reach, through what it names, what those name, and so
/// on (a module never counts as reaching itself).
#[derive(Debug, Clone, Copy)]
struct Rule {
    modules: Modules,
    forbidden: Modules,
    why: &'static str,
}

const fn rule(modules: Modules, forbidden: Modules, why: &'static str) -> Rule {
    Rule {
        modules,
        forbidden,
        why,
    }
}

use Modules::{AllBut, Only};

/// The tools over frames: what only the command line and the run layer may reach.
const TOOLS: &[&str] = &[
    "run", "compare", "bench", "export", "diff", "pages", "report", "cli",
];

/// The frame loop and everything it stands on.
const KERNEL: &[&str] = &[
    "frame", "anim", "geometry", "accel", "lod", "render", "texture", "scene", "simd",
];

/// The shared leaves: they import nothing else from the crate.
const LEAVES: &[&str] = &[
    "record",
    "colour",
    "atomic_file",
    "csv",
    "markup",
    "percentiles",
    "chart",
    "large_pages",
];

/// Every rule, one per line, each checked on the transitive closure of imports.
#[rustfmt::skip]
const RULES: &[Rule] = &[
    rule(AllBut(&["cli"]), Only(&["cli"]), "nothing below the command line imports it"),
    rule(AllBut(&["cli"]), Only(&["run"]), "the run layer is the top of the library: only the CLI drives it"),
    rule(AllBut(&["cli", "run"]), Only(&["diff", "pages", "report"]), "below the CLI only the run layer calls diff, pages and report (and they do not call each other)"),
    rule(Only(KERNEL), Only(TOOLS), "the frame loop and the modules under it reach no tool"),
    rule(Only(LEAVES), AllBut(&[]), "a shared leaf imports nothing from the crate"),
    rule(Only(&["metrics"]), AllBut(LEAVES), "image metrics stand on the shared leaves alone (the sRGB encoding is colour's, not the renderer's)"),
    rule(Only(&["scene"]), AllBut(&["anim", "texture", "simd"]), "loaders know only sampling types and texture pyramids (whose filters run through the SIMD dispatch)"),
    rule(Only(&["simd"]), AllBut(&["simd"]), "the SIMD dispatch and lanes stand on nothing else in the crate"),
    rule(Only(&["geometry"]), Only(&["render", "scene", "frame"]), "the kernel's ground floor (triangle arrays, hit record, placements) stands below the renderer, the description and the frame loop"),
    rule(Only(&["accel"]), Only(&["render", "scene"]), "the trees know triangles and placements, not materials, lights or files"),
    rule(Only(&["render", "lod", "accel"]), Only(&["scene"]), "no file format reaches the hot loop (render types are built in frame::appearance)"),
    rule(Only(&["lod"]), Only(&["render"]), "lod takes the pixel footprint it needs (lod::ViewFrame), not the render camera"),
];

/// Where library code may print (everything else reports values or errors).
const PRINTERS: &[&str] = &["src/cli", "src/main.rs"];

/// What writes to the terminal.
const PRINTING: &[&str] = &[
    "print!(",
    "println!(",
    "eprint!(",
    "eprintln!(",
    "dbg!(",
    "stdout()",
    "stderr()",
    "indicatif",
];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The top-level modules of `src/` (folders and files, without `lib.rs` and `main.rs`).
fn top_level_modules(src: &Path) -> BTreeSet<String> {
    std::fs::read_dir(src)
        .expect("src/ lists")
        .map(|e| e.expect("directory entry").path())
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?.to_owned();
            match name.strip_suffix(".rs") {
                Some(stem) => (stem != "lib" && stem != "main").then(|| stem.to_owned()),
                None => p.is_dir().then_some(name),
            }
        })
        .collect()
}

/// Byte offsets in `text` where a path names a top-level module after `crate::`, and
/// which: directly (`crate::scene::X`) or as a top-level item of a grouped import, which
/// may span lines (`use crate::{geometry, scene::X};`).
fn named_modules(text: &str) -> Vec<(usize, String)> {
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let first_ident = |s: &str| -> Option<String> {
        let s = s.trim_start();
        let end = s.find(|c: char| !is_ident(c)).unwrap_or(s.len());
        (end > 0).then(|| s[..end].to_owned())
    };
    let mut found = Vec::new();
    for (i, m) in text.match_indices("crate::") {
        let rest = &text[i + m.len()..];
        match rest.strip_prefix('{') {
            Some(group) => {
                for item in top_level_items(group) {
                    found.extend(first_ident(item).map(|name| (i, name)));
                }
            }
            None => found.extend(first_ident(rest).map(|name| (i, name))),
        }
    }
    found
}

/// The comma-separated items of a `{...}` group at its own depth (text after the `{`, up to
/// the matching `}`); nested groups stay inside their item.
fn top_level_items(group: &str) -> impl Iterator<Item = &str> {
    let mut depth = 0;
    let mut start = 0;
    let mut items = Vec::new();
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.into_iter()
}

/// A file's library code: its text with every `#[cfg(test)]` item blanked out (replaced by
/// spaces, newlines kept, so offsets and line numbers stay), and the names of the modules
/// it declares test-only (`#[cfg(test)] mod name;`, whose files are test code).
fn library_code(text: &str) -> (String, Vec<String>) {
    const MARK: &str = "#[cfg(test)]";
    let mut code = text.to_owned();
    let mut test_modules = Vec::new();
    let mut from = 0;
    while let Some(at) = text[from..].find(MARK).map(|i| from + i) {
        let end = item_end(text, at + MARK.len());
        let item = &text[at + MARK.len()..end];
        if item.trim_end().ends_with(';') {
            let words: Vec<&str> = item.split_whitespace().collect();
            if let Some(k) = words.iter().position(|w| *w == "mod") {
                test_modules.extend(words.get(k + 1).map(|n| n.trim_end_matches(';').to_owned()));
            }
        }
        let blank: String = text[at..end]
            .chars()
            .map(|c| if c == '\n' { '\n' } else { ' ' })
            .collect();
        code.replace_range(at..end, &blank);
        from = end;
    }
    (code, test_modules)
}

/// Where the item starting at `start` ends: after its `;` when one comes before any `{`,
/// else after the `}` that closes its first `{`. Strings, characters and comments are
/// skipped, so braces inside them do not count.
fn item_end(text: &str, start: usize) -> usize {
    let bytes = text.as_bytes();
    let mut depth = 0usize;
    let mut i = start;
    while i < bytes.len() {
        match bytes[i] {
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                i = text[i..].find('\n').map_or(bytes.len(), |n| i + n);
                continue;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                i = text[i + 2..]
                    .find("*/")
                    .map_or(bytes.len(), |n| i + 2 + n + 2);
                continue;
            }
            b'r' if !is_ident_byte(bytes, i) && raw_string_start(bytes, i).is_some() => {
                let hashes = raw_string_start(bytes, i).unwrap_or(0);
                let close = format!("\"{}", "#".repeat(hashes));
                let body = i + 2 + hashes;
                i = text[body..]
                    .find(&close)
                    .map_or(bytes.len(), |n| body + n + close.len());
                continue;
            }
            b'"' => {
                i += 1;
                while i < bytes.len() && bytes[i] != b'"' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
            }
            // A character literal ('{', '\'', '\u{7b}'), not a lifetime.
            b'\'' if bytes.get(i + 2) == Some(&b'\'') => i += 2,
            b'\'' if bytes.get(i + 1) == Some(&b'\\') => {
                i = text[i + 2..].find('\'').map_or(bytes.len(), |n| i + 2 + n);
            }
            b';' if depth == 0 => return i + 1,
            b'{' => depth += 1,
            b'}' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    bytes.len()
}

/// Whether the byte before `i` continues an identifier (so `r` at `i` is not a prefix).
fn is_ident_byte(bytes: &[u8], i: usize) -> bool {
    i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_')
}

/// `Some(number of #)` when a raw string starts at `i` (`r"`, `r#"`, ...).
fn raw_string_start(bytes: &[u8], i: usize) -> Option<usize> {
    let hashes = bytes[i + 1..].iter().take_while(|&&b| b == b'#').count();
    (bytes.get(i + 1 + hashes) == Some(&b'"')).then_some(hashes)
}

/// One library source file: its path, its library code and its top-level module.
struct Source {
    path: PathBuf,
    code: String,
    module: String,
}

/// Every library file under `src/` (test-only files left out), with its library code.
fn library_sources(src: &Path) -> Vec<Source> {
    let modules = top_level_modules(src);
    let mut sources = Vec::new();
    let mut test_only: BTreeSet<PathBuf> = BTreeSet::new();
    for path in files::files_with_extension(src, "rs") {
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let (code, test_modules) = library_code(&text);
        // A child module of `x/mod.rs` lives in `x/`, of `x.rs` in `x/` too.
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        let parent = path.parent().unwrap_or(src);
        let child_dir = if stem == "mod" || stem == "lib" {
            parent.to_path_buf()
        } else {
            parent.join(stem)
        };
        for name in test_modules {
            test_only.insert(child_dir.join(format!("{name}.rs")));
            test_only.insert(child_dir.join(&name));
        }
        let relative = path.strip_prefix(src).unwrap_or(&path);
        let first = relative
            .components()
            .next()
            .and_then(|c| c.as_os_str().to_str());
        let module = first.unwrap_or_default().trim_end_matches(".rs").to_owned();
        sources.push(Source { path, code, module });
    }
    sources.retain(|s| !test_only.iter().any(|t| s.path.starts_with(t)));
    sources.retain(|s| modules.contains(&s.module) || s.module == "lib" || s.module == "main");
    sources
}

/// The module graph: per module, each module it names and where it first does
/// (`file:line: text`).
type Graph = BTreeMap<String, BTreeMap<String, String>>;

fn import_graph(src: &Path) -> Graph {
    let modules = top_level_modules(src);
    let mut graph: Graph = modules
        .iter()
        .map(|m| (m.clone(), BTreeMap::new()))
        .collect();
    for source in library_sources(src) {
        let Some(edges) = graph.get_mut(&source.module) else {
            continue;
        };
        for (offset, name) in named_modules(&source.code) {
            if name == source.module || !modules.contains(&name) {
                continue;
            }
            edges.entry(name).or_insert_with(|| {
                let line = source.code[..offset].matches('\n').count() + 1;
                let shown = source.code[offset..].lines().next().unwrap_or_default();
                format!("{}:{line}: {}", source.path.display(), shown.trim())
            });
        }
    }
    graph
}

/// The modules `from` reaches (the transitive closure of its imports), each with the
/// shortest path that reaches it (the `file:line` of every step).
fn reached(graph: &Graph, from: &str) -> BTreeMap<String, Vec<String>> {
    let mut paths: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut queue = VecDeque::from([from.to_owned()]);
    while let Some(module) = queue.pop_front() {
        let here = paths.get(&module).cloned().unwrap_or_default();
        for (next, place) in graph.get(&module).into_iter().flatten() {
            if next == from || paths.contains_key(next) {
                continue;
            }
            let mut path = here.clone();
            path.push(format!("{module} -> {next} ({place})"));
            paths.insert(next.clone(), path);
            queue.push_back(next.clone());
        }
    }
    paths
}

fn selected<'a>(modules: Modules, all: &'a BTreeSet<String>) -> Vec<&'a str> {
    all.iter()
        .map(String::as_str)
        .filter(|m| match modules {
            Modules::Only(names) => names.contains(m),
            Modules::AllBut(names) => !names.contains(m),
        })
        .collect()
}

/// Every way `rule` is broken in `graph`.
fn violations(graph: &Graph, rule: &Rule) -> Vec<String> {
    let all: BTreeSet<String> = graph.keys().cloned().collect();
    let forbidden = selected(rule.forbidden, &all);
    let mut found = Vec::new();
    for module in selected(rule.modules, &all) {
        for (target, path) in reached(graph, module) {
            if target != module && forbidden.contains(&target.as_str()) {
                found.push(format!(
                    "src/{module} reaches {target}:\n  {}",
                    path.join("\n  ")
                ));
            }
        }
    }
    found
}

#[test]
fn every_layering_rule_holds() {
    let src = src();
    let graph = import_graph(&src);
    let all: BTreeSet<String> = graph.keys().cloned().collect();
    let mut broken = Vec::new();
    for rule in RULES {
        // A rule that names a module that does not exist checks nothing: fail instead.
        for modules in [rule.modules, rule.forbidden] {
            let (Modules::Only(names) | Modules::AllBut(names)) = modules;
            for name in names {
                assert!(
                    all.contains(*name),
                    "rule {:?} names no module `{name}`",
                    rule.why
                );
            }
        }
        for v in violations(&graph, rule) {
            broken.push(format!("{}:\n{v}", rule.why));
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n\n"));
}

#[test]
fn nothing_below_the_command_line_prints() {
    let src = src();
    let root = src.parent().expect("src/ has a parent").to_path_buf();
    let mut found = Vec::new();
    for source in library_sources(&src) {
        let relative = source.path.strip_prefix(&root).unwrap_or(&source.path);
        if PRINTERS.iter().any(|p| relative.starts_with(p)) {
            continue;
        }
        for (number, line) in source.code.lines().enumerate() {
            let code = line.split("//").next().unwrap_or_default();
            if PRINTING.iter().any(|p| code.contains(p)) {
                found.push(format!(
                    "{}:{}: {}",
                    relative.display(),
                    number + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "library code below src/cli prints (report a value or an error, or take a `run::SequenceProgress`):\n{}",
        found.join("\n")
    );
}

#[test]
fn import_scan_finds_direct_grouped_and_macro_paths() {
    let names =
        |text: &str| -> Vec<String> { named_modules(text).into_iter().map(|(_, n)| n).collect() };
    assert_eq!(
        names("use crate::scene::{LightDesc, LightKind};"),
        ["scene"]
    );
    assert_eq!(
        names("    kind: crate::scene::LightKind::Point,"),
        ["scene"]
    );
    assert_eq!(
        names("use crate::{geometry::FrameTriangles, scene};"),
        ["geometry", "scene"]
    );
    assert_eq!(
        names("use crate::{\n    geometry::{A, B},\n    scene::MaterialDesc,\n};"),
        ["geometry", "scene"]
    );
    assert_eq!(names("$crate::lod::LodMethod::Paper"), ["lod"]);
    assert_eq!(names("use crate::scenery::Thing;"), ["scenery"]);
    assert_eq!(
        names("use crate::{geometry::{scene_like, X}, render};"),
        ["geometry", "render"]
    );
    assert!(names("// the scene description").is_empty());
}

#[test]
fn test_code_is_left_out_and_offsets_stay() {
    let text = "use crate::a;\n#[cfg(test)]\nmod tests {\n    use crate::b;\n    fn f() { let _ = '{'; let _ = \"}\"; let _ = r#\"}\"#; }\n    // }\n    fn g<'a>(x: &'a str) -> &'a str { x }\n}\nuse crate::c;\n#[cfg(test)]\nmod helpers;\n#[cfg(test)]\n#[allow(dead_code)]\nuse crate::d;\nfn h() { println!(\"{}\", 1) }\n";
    let (code, test_modules) = library_code(text);
    assert_eq!(code.len(), text.len());
    assert_eq!(code.lines().count(), text.lines().count());
    let names: Vec<String> = named_modules(&code).into_iter().map(|(_, n)| n).collect();
    assert_eq!(names, ["a", "c"]);
    assert_eq!(test_modules, ["helpers"]);
    assert!(code.contains("fn h() { println!"));
}

#[test]
fn rules_follow_paths_through_other_modules() {
    let edge = |to: &str| (to.to_owned(), format!("src/x.rs:1: crate::{to}"));
    let graph: Graph = [
        ("lod", vec![edge("geometry")]),
        ("geometry", vec![edge("render")]),
        ("render", vec![edge("lod")]),
        ("record", vec![]),
    ]
    .into_iter()
    .map(|(m, edges)| (m.to_owned(), edges.into_iter().collect()))
    .collect();
    let lod_must_not_reach = |forbidden| Rule {
        modules: Modules::Only(&["lod"]),
        forbidden: Modules::Only(forbidden),
        why: "test",
    };
    // `lod` names only `geometry`, but reaches `render` through it: the path names each step.
    let found = violations(&graph, &lod_must_not_reach(&["render"]));
    assert_eq!(found.len(), 1);
    assert!(found[0].contains("lod -> geometry") && found[0].contains("geometry -> render"));
    // A direct import is a path of one step.
    let found = violations(&graph, &lod_must_not_reach(&["geometry"]));
    assert_eq!(found.len(), 1);
    assert!(found[0].contains("lod -> geometry") && !found[0].contains("-> render"));
    // A module reaching itself through a cycle is no violation; a leaf reaches nothing.
    let leaves = Rule {
        modules: Modules::Only(&["record", "lod"]),
        forbidden: Modules::Only(&["lod", "record"]),
        why: "test",
    };
    assert!(violations(&graph, &leaves).is_empty());
}
