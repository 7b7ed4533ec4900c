//! The "Examples" that end each command's `--help` (clap `after_help`). Kept here, apart
//! from the argument structs, so the flags and their examples are edited independently.
//! `tests/cli_help.rs` checks that every subcommand has such a section; every example
//! must be a command the current flags accept (the same test parses each one).

/// Ends `mipray --help`.
pub const MIPRAY: &str = "\
Examples:
  mipray render default --frames 0..12 --size 320x180   Render 12 frames into out/default/paper/
  mipray help render                                     The flags of one command";

pub const RENDER: &str = "\
Examples:
  mipray render default --frames 0..24 --size 320x180 --out out/shot
  mipray render kitchen --lod cones --resume --check refs/kitchen --junit check.xml";

pub const BENCH: &str = "\
Examples:
  mipray bench default --frames 0..8 --size 320x180 --methods none,paper --threads 1,2
  mipray bench default --frames 0 --rays all --lights 1";

pub const REPORT: &str = "\
Examples:
  mipray report out/default/paper
  mipray report out/shot --expect-frames 0..480 --svg shot.svg";

pub const DIFF: &str = "\
Examples:
  mipray diff refs/default out/default/paper
  mipray diff refs/default out/default/paper --metric max-abs --threshold 0 --junit diff.xml";

pub const COMPARE: &str = "\
Examples:
  mipray compare default --frames 0..4 --size 320x180 --save-frames
  mipray compare kitchen --frames 0..8 --lights 1..6 --methods none,paper";

pub const EXPORT: &str = "\
Examples:
  mipray export default --frames 24 --out frames/
  mipray export default --frames 0 --size 320x180 --rays --format ply";

pub const INFO: &str = "\
Examples:
  mipray info default
  mipray info path/to/scene.glb";

pub const COMPLETIONS: &str = "\
Examples:
  mipray completions bash > ~/.local/share/bash-completion/completions/mipray
  mipray completions zsh > ~/.zfunc/_mipray";

pub const MAN: &str = "\
Examples:
  mipray man > mipray.1 && man -l mipray.1
  mipray man render | man -l -";
