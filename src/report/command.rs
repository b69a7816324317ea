//! What a command of `forced-vi-report` is.
//!
//! A command is a [`Command`]: its name on the command line, its help line, the README
//! sections it writes and the function that runs it. Each command module defines its own
//! `COMMAND`, and [`COMMANDS`] lists them. The binary builds its command line from that list,
//! and [`readme`](super::readme) orders the sections of `README.md` by it. A new command is
//! therefore a module of its own plus one line in [`COMMANDS`]; nothing else changes.

use super::{Options, ReportError, COMMANDS};

/// Reads the process's heap-allocation count (the binary's counting allocator).
pub type AllocCounter = fn() -> u64;

/// What only the binary can give a command.
#[derive(Clone, Copy, Debug, Default)]
pub struct Hooks {
    /// Reads the binary's counting allocator (`step-cost` reports allocations per step).
    pub allocations: Option<AllocCounter>,
}

/// One command of `forced-vi-report`.
#[derive(Clone, Copy, Debug)]
pub struct Command {
    /// The name on the command line (`forced-vi-report <name>`).
    pub name: &'static str,
    /// The help line.
    pub about: &'static str,
    /// The README sections it writes (`sections/<name>.md`), in README order.
    pub sections: &'static [&'static str],
    /// Runs the command and returns the line the binary prints on success.
    pub run: fn(&Options, &Hooks) -> Result<String, ReportError>,
}

/// The README sections of every command, in README order.
pub fn section_order() -> impl Iterator<Item = &'static str> {
    COMMANDS.iter().flat_map(|c| c.sections.iter().copied())
}

/// The command called `name`.
pub fn find(name: &str) -> Option<&'static Command> {
    COMMANDS.iter().find(|c| c.name == name)
}
