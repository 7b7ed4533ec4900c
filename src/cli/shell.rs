//! `mipray completions <shell>` and `mipray man [command]`: shell completion scripts and
//! roff man pages, both generated from the same clap definition as the parser, so they
//! cannot drift from the flags. Both print to stdout (redirect them where the shell or
//! `man` looks).

use std::io::Write;

use anyhow::{Context, Result};
use clap::{Args, CommandFactory};
use clap_complete::Shell;

use super::Cli;
use super::args::usage;

#[derive(Args, Debug, Clone)]
pub struct CompletionsArgs {
    /// The shell to write the completion script for.
    #[arg(value_enum)]
    pub shell: Shell,
}

#[derive(Args, Debug, Clone)]
pub struct ManArgs {
    /// Print the page of this command (`mipray-render(1)`, ...) instead of `mipray(1)`.
    pub command: Option<String>,
}

/// `mipray completions`: the completion script on stdout.
pub fn completions(args: &CompletionsArgs) -> Result<()> {
    let mut command = Cli::command();
    let mut out = Vec::new();
    clap_complete::generate(args.shell, &mut command, "mipray", &mut out);
    write_stdout(&out)
}

/// `mipray man`: the roff man page of `mipray` or of one of its commands on stdout.
pub fn man(args: &ManArgs) -> Result<()> {
    let mut out = Vec::new();
    man_page(args.command.as_deref(), &mut out)?;
    write_stdout(&out)
}

/// Renders the man page of `mipray` (`None`) or of `mipray <command>`: an unknown command
/// is an error that lists the known ones.
pub fn man_page(command: Option<&str>, out: &mut Vec<u8>) -> Result<()> {
    let mut root = Cli::command();
    // Builds the parser's derived parts (the `help` subcommand, version flags, display
    // names such as `mipray-render`) so the page shows what `--help` shows.
    root.build();
    let page = match command {
        None => root,
        Some(name) => match root.find_subcommand(name) {
            Some(sub) => sub.clone(),
            None => {
                let known: Vec<&str> = root.get_subcommands().map(|c| c.get_name()).collect();
                return Err(usage(format!(
                    "man {name}: no such command (one of {})",
                    known.join(", ")
                )));
            }
        },
    };
    // Every page names the program and its version in the footer (a subcommand has no
    // version of its own, so clap_mangen would print its bare name there).
    clap_mangen::Man::new(page)
        .source(format!("mipray {}", env!("CARGO_PKG_VERSION")))
        .render(out)
        .context("rendering the man page")
}

fn write_stdout(bytes: &[u8]) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(bytes).context("writing to stdout")?;
    stdout.flush().context("writing to stdout")
}
