//! The documented commands run: every command in a fenced block marked `runnable` in
//! README.md and `docs/src/**/*.md` is run with the built binary and must succeed, so the
//! guide cannot rot as the flags change.
//!
//! The rules (also in CONTRIBUTING.md, "Runnable examples in the docs"):
//! - a block is runnable when its info string has the word `runnable`: ```` ```sh runnable ````;
//! - each of its lines is one `mipray ...` command (a trailing `\` continues a line, `#`
//!   starts a comment); `mipray` is replaced by this build's binary. Anything else (a
//!   `cargo` line, a pipe, a redirection, `&&`, a `$VARIABLE`) is an error, so a block
//!   cannot be marked runnable and silently not run;
//! - the blocks of one file run in order, in one fresh temporary folder (so a page can
//!   render and then diff what it rendered), with `animations/` linked into it; a scene
//!   name such as `default` resolves as it does anywhere;
//! - an argument under `../shared/` names the read-only test data: it is rewritten to
//!   `tests/common/shared_data.rs`'s folder, and when that is absent the file's commands
//!   are skipped with a printed reason (a failure when `CI` is set).
//!
//! Keep runnable blocks small (a few frames at sizes like 160x90): this test runs all of them.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use common::shared_data::shared_path;

/// One command of a runnable block: where it is written and its arguments after `mipray`.
#[derive(Debug, Clone, PartialEq)]
struct DocCommand {
    file: PathBuf,
    line: usize,
    args: Vec<String>,
}

/// Whether a fence's info string marks the block runnable (`sh runnable`, `sh,runnable`).
fn is_runnable(info: &str) -> bool {
    info.split(|c: char| c.is_whitespace() || c == ',')
        .any(|word| word == "runnable")
}

/// The runnable commands of one Markdown text, in order; an error names the line of a
/// runnable block that is not a plain `mipray` command.
fn runnable_commands(file: &Path, text: &str) -> Result<Vec<DocCommand>, String> {
    let mut commands = Vec::new();
    // (fence marker, runnable) while inside a block.
    let mut open: Option<(String, bool)> = None;
    // A command continued with `\`: its first line and the text so far.
    let mut pending: Option<(usize, String)> = None;
    for (index, raw) in text.lines().enumerate() {
        let number = index + 1;
        let trimmed = raw.trim_start();
        match &open {
            None => {
                if let Some(marker) = fence_marker(trimmed) {
                    let info = trimmed[marker.len()..].trim();
                    open = Some((marker, is_runnable(info)));
                }
            }
            Some((marker, runnable)) => {
                if trimmed.starts_with(marker.as_str()) && trimmed[marker.len()..].trim().is_empty()
                {
                    if let Some((line, _)) = pending {
                        return Err(format!(
                            "{}:{line}: the block ends inside a continued line",
                            file.display()
                        ));
                    }
                    open = None;
                    continue;
                }
                if !runnable {
                    continue;
                }
                let (line, mut joined) = pending.take().unwrap_or((number, String::new()));
                let text = raw.trim_end();
                if let Some(head) = text.strip_suffix('\\') {
                    joined.push_str(head);
                    joined.push(' ');
                    pending = Some((line, joined));
                    continue;
                }
                joined.push_str(text);
                let words = split_words(&joined)
                    .map_err(|problem| format!("{}:{line}: {problem}", file.display()))?;
                match words.split_first() {
                    None => {}
                    Some((program, args)) if program == "mipray" => commands.push(DocCommand {
                        file: file.to_path_buf(),
                        line,
                        args: args.to_vec(),
                    }),
                    Some((program, _)) => {
                        return Err(format!(
                            "{}:{line}: `{program}`: a runnable block holds only `mipray` commands \
                             (mark the block plain `sh` to show other commands)",
                            file.display()
                        ));
                    }
                }
            }
        }
    }
    if open.is_some() {
        return Err(format!(
            "{}: a fenced block is never closed",
            file.display()
        ));
    }
    Ok(commands)
}

/// The fence that opens a block on this line (three or more backticks or tildes).
fn fence_marker(line: &str) -> Option<String> {
    for fence in ['`', '~'] {
        let count = line.chars().take_while(|&c| c == fence).count();
        if count >= 3 {
            return Some(std::iter::repeat_n(fence, count).collect());
        }
    }
    None
}

/// Splits a command line into words: whitespace separates, single and double quotes group,
/// `#` at the start of a word begins a comment. What a shell would do beyond that (pipes,
/// redirections, variables, globs, command lists) is refused, so the test never runs a
/// command differently from how a reader's shell would.
fn split_words(line: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => words.extend(word.take()),
            '#' if word.is_none() => break,
            '\'' | '"' => {
                let current = word.get_or_insert_with(String::new);
                loop {
                    match chars.next() {
                        Some(q) if q == c => break,
                        Some(q) => current.push(q),
                        None => return Err(format!("unclosed {c} quote")),
                    }
                }
            }
            '|' | '>' | '<' | '&' | ';' | '$' | '`' | '*' | '?' | '\\' | '(' | ')' => {
                return Err(format!(
                    "`{c}`: runnable commands are plain words (no pipes, redirections, \
                     variables, globs or command lists)"
                ));
            }
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    words.extend(word);
    Ok(words)
}

/// README.md and every Markdown file under docs/src/, sorted.
fn documented_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = vec![root.join("README.md")];
    files.extend(common::files::files_with_extension(
        &root.join("docs/src"),
        "md",
    ));
    files.sort();
    files
}

/// The command's arguments with `../shared/...` rewritten to the test data; `None` (after
/// the skip message) when that data is absent.
fn with_shared_data(args: &[String]) -> Option<Vec<String>> {
    args.iter()
        .map(|arg| match arg.strip_prefix("../shared/") {
            Some(relative) => shared_path(relative).map(|p| p.display().to_string()),
            None => Some(arg.clone()),
        })
        .collect()
}

/// Runs one file's commands in order in a fresh folder; the failures, described.
fn run_file(file: &Path, commands: &[DocCommand]) -> Vec<String> {
    let work = tempfile::tempdir().expect("a temporary folder");
    let animations = Path::new(env!("CARGO_MANIFEST_DIR")).join("animations");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&animations, work.path().join("animations"))
        .expect("linking animations/ into the temporary folder");
    let mut failures = Vec::new();
    for command in commands {
        let Some(args) = with_shared_data(&command.args) else {
            println!(
                "skipping the rest of {}: it needs ../shared",
                file.display()
            );
            break;
        };
        let output = Command::new(env!("CARGO_BIN_EXE_mipray"))
            .args(&args)
            .current_dir(work.path())
            .output()
            .expect("the mipray binary starts");
        let place = format!("{}:{}", command.file.display(), command.line);
        println!(
            "{place}: mipray {} -> {}",
            command.args.join(" "),
            output.status
        );
        if !output.status.success() {
            failures.push(format!(
                "{place}: `mipray {}` exited with {}\nstderr:\n{}",
                command.args.join(" "),
                output.status,
                String::from_utf8_lossy(&output.stderr)
            ));
            // Later commands of the page usually read what this one wrote.
            break;
        }
    }
    failures
}

#[test]
fn every_runnable_command_in_the_docs_succeeds() {
    let mut parsed = Vec::new();
    let mut errors = Vec::new();
    for file in documented_files() {
        let text = std::fs::read_to_string(&file).expect("a readable Markdown file");
        match runnable_commands(&file, &text) {
            Ok(commands) => parsed.push((file, commands)),
            Err(error) => errors.push(error),
        }
    }
    assert!(
        errors.is_empty(),
        "malformed runnable blocks:\n{}",
        errors.join("\n")
    );
    let total: usize = parsed.iter().map(|(_, c)| c.len()).sum();
    // The README's quick start alone has six: far fewer means the marker stopped matching.
    assert!(
        total >= 6,
        "only {total} runnable commands found in the docs"
    );
    let readme = &parsed[0];
    assert!(
        readme.0.ends_with("README.md") && readme.1.len() >= 3,
        "README.md's quick start should be runnable"
    );
    // Files run on threads of their own: each has its own folder, and they are small.
    let failures: Vec<String> = std::thread::scope(|scope| {
        let handles: Vec<_> = parsed
            .iter()
            .filter(|(_, commands)| !commands.is_empty())
            .map(|(file, commands)| scope.spawn(move || run_file(file, commands)))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a docs runner thread"))
            .collect()
    });
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn the_parser_finds_runnable_commands_and_only_them() {
    let text = "\
Text.

```sh
cargo run --release
```

```sh runnable
mipray render default --frames 0..2 \\
    --size 32x18   # a comment
# a whole-line comment
mipray diff 'a b' \"c\"
```

~~~sh,runnable
mipray info default
~~~
";
    let file = Path::new("x.md");
    let commands = runnable_commands(file, text).unwrap();
    let args: Vec<Vec<&str>> = commands
        .iter()
        .map(|c| c.args.iter().map(String::as_str).collect())
        .collect();
    assert_eq!(
        args,
        [
            vec!["render", "default", "--frames", "0..2", "--size", "32x18"],
            vec!["diff", "a b", "c"],
            vec!["info", "default"],
        ]
    );
    assert_eq!(
        commands.iter().map(|c| c.line).collect::<Vec<_>>(),
        [8, 11, 15]
    );
}

#[test]
fn a_runnable_block_refuses_what_it_would_not_run() {
    let file = Path::new("x.md");
    for body in [
        "cargo run --release",
        "mipray render | head",
        "mipray completions bash > out",
        "mipray render $SCENE",
        "mipray render 'open",
    ] {
        let text = format!("```sh runnable\n{body}\n```\n");
        let error = runnable_commands(file, &text).expect_err(body);
        assert!(error.starts_with("x.md:2: "), "{body}: {error}");
    }
    assert!(runnable_commands(file, "```sh runnable\nmipray info default\n").is_err());
}
