//! The help, completions and man pages: every command's `--help` ends with examples that
//! the current parser accepts, and `mipray completions` / `mipray man` produce what the
//! shells and `man` read.

use std::process::{Command, Output};

use clap::{CommandFactory, Parser};
use mipray::cli::Cli;

fn mipray(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mipray"))
        .args(args)
        .output()
        .expect("the mipray binary starts")
}

fn stdout(output: &Output) -> String {
    assert!(
        output.status.success(),
        "exit {}: {}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout.clone()).expect("UTF-8 output")
}

/// The names of mipray's commands (clap's own `help` left out: it has no flags to show).
fn command_names() -> Vec<String> {
    Cli::command()
        .get_subcommands()
        .map(|c| c.get_name().to_owned())
        .collect()
}

/// The example command lines at the end of a help text: the lines after `Examples:`, each
/// cut at a redirection, pipe or `&&`, and at a run of spaces (a description follows).
fn examples(help: &str) -> Vec<Vec<String>> {
    let (_, section) = help
        .split_once("\nExamples:\n")
        .expect("an Examples section");
    section
        .lines()
        .filter(|line| !line.trim().is_empty())
        .map(|line| {
            let command = line.trim().split("   ").next().unwrap_or_default();
            command
                .split_whitespace()
                .take_while(|w| !matches!(*w, ">" | "|" | "&&"))
                .map(str::to_owned)
                .collect()
        })
        .collect()
}

#[test]
fn every_command_help_ends_with_examples_the_parser_accepts() {
    let names = command_names();
    assert!(names.len() >= 9, "commands: {names:?}");
    let mut helps = vec![(String::from("mipray"), stdout(&mipray(&["--help"])))];
    for name in &names {
        helps.push((name.clone(), stdout(&mipray(&[name, "--help"]))));
        // The short help (-h) ends with them too.
        let short = stdout(&mipray(&[name, "-h"]));
        assert!(
            short.contains("\nExamples:\n"),
            "mipray {name} -h: no examples"
        );
    }
    for (name, help) in helps {
        let lines = examples(&help);
        assert!(
            (1..=3).contains(&lines.len()),
            "mipray {name} --help: {} examples",
            lines.len()
        );
        for words in lines {
            assert_eq!(words[0], "mipray", "mipray {name}: example {words:?}");
            if name != "mipray" {
                assert_eq!(words[1], name, "mipray {name}: example of another command");
            }
            // `mipray help render` parses to clap's request to show help.
            let shows_help = |e: &clap::Error| e.kind() == clap::error::ErrorKind::DisplayHelp;
            if let Err(error) = Cli::try_parse_from(&words)
                .map(drop)
                .or_else(|e| if shows_help(&e) { Ok(()) } else { Err(e) })
            {
                panic!("mipray {name}: example {words:?} does not parse:\n{error}");
            }
        }
        // The section is the last thing printed.
        let tail = help.rsplit_once("\nExamples:\n").unwrap().1;
        assert!(
            tail.lines()
                .all(|l| l.trim().is_empty() || l.trim_start().starts_with("mipray ")),
            "mipray {name}: text after the examples:\n{tail}"
        );
    }
}

#[test]
fn completions_cover_every_command_for_every_shell() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let script = stdout(&mipray(&["completions", shell]));
        for name in command_names() {
            assert!(script.contains(&name), "{shell}: no `{name}` in the script");
        }
        // Flags by their long name (fish writes `-l resume`, the others `--resume`).
        for flag in ["resume", "fail-fast", "reference-spp", "expect-frames"] {
            assert!(script.contains(flag), "{shell}: no --{flag} in the script");
        }
    }
    let bash = stdout(&mipray(&["completions", "bash"]));
    assert!(
        bash.contains("complete -F _mipray"),
        "not a bash completion:\n{bash}"
    );
    // Bash itself checks the script's syntax where it is installed (it is on CI's image).
    if let Ok(status) = Command::new("bash").args(["-n", "-c", &bash]).status() {
        assert!(status.success(), "bash -n rejects the completion script");
    }
    let unknown = mipray(&["completions", "tcsh"]);
    assert_eq!(
        unknown.status.code(),
        Some(2),
        "an unknown shell is a usage error"
    );
}

#[test]
fn man_pages_for_mipray_and_each_command() {
    let page = stdout(&mipray(&["man"]));
    assert!(page.contains(".TH mipray 1"), "no title line:\n{page}");
    for name in command_names() {
        assert!(page.contains(&name), "mipray(1) does not list `{name}`");
        let sub = stdout(&mipray(&["man", &name]));
        assert!(
            sub.contains(&format!(".TH mipray-{name} 1")),
            "mipray man {name}: no title line:\n{sub}"
        );
        assert!(sub.contains("Examples:"), "mipray man {name}: no examples");
        assert!(
            sub.contains(&format!("\"mipray {}\"", env!("CARGO_PKG_VERSION"))),
            "mipray man {name}: the footer should name mipray and its version"
        );
    }
    let render = stdout(&mipray(&["man", "render"]));
    for flag in ["resume", "check", "frames", "lod"] {
        assert!(
            render.contains(&format!("\\-\\-{flag}")),
            "mipray-render(1) lacks --{flag}"
        );
    }
    let unknown = mipray(&["man", "rendr"]);
    assert_eq!(unknown.status.code(), Some(2));
    let error = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        error.contains("rendr") && error.contains("render"),
        "the error should name the command and the known ones: {error}"
    );
}
