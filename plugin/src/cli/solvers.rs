//! `volscatter solvers`: the solvers as a short table for people (name, GPU, lights, what it is
//! for); `--json` prints the registry (the same document as `vs_solvers_json`): every solver's
//! settings with defaults, ranges and help, the lights it handles, its presets and whether it has
//! a GPU backend.

use std::io::Write;

use clap::Args;
use volscatter_core::solvers::registry::{self, LightType, SolverEntry};
use volscatter_core::{Error, Result};

#[derive(Args)]
pub struct SolversArgs {
    /// Print the registry as JSON (settings, defaults, ranges, presets): what hosts and scripts read.
    #[arg(long)]
    json: bool,
}

pub fn run(args: SolversArgs) -> Result<()> {
    let text = if args.json {
        serde_json::to_string_pretty(&registry::to_json()).map_err(|e| Error::InvalidArgument(e.to_string()))?
    } else {
        table(registry::SOLVERS, 100)
    };
    // Written, not println!'d: a closed pipe (`volscatter solvers | head`) is an error, not a panic.
    writeln!(std::io::stdout().lock(), "{text}").map_err(|e| Error::io("<stdout>", e))
}

/// One row per solver, its help wrapped under the last column so that no line passes `width`.
fn table(solvers: &[SolverEntry], width: usize) -> String {
    let name_w = solvers.iter().map(|s| s.name.len()).max().unwrap_or(0).max("solver".len());
    let rows: Vec<(&str, &str, String, &str)> =
        solvers.iter().map(|s| (s.name, if s.gpu { "yes" } else { "no" }, lights(s.lights), s.help)).collect();
    let lights_w = rows.iter().map(|r| r.2.len()).max().unwrap_or(0).max("lights".len());
    let indent = name_w + 2 + "GPU".len() + 2 + lights_w + 2;
    let mut out = format!("{:name_w$}  GPU  {:lights_w$}  what it is for\n", "solver", "lights");
    for (name, gpu, lights, help) in rows {
        let mut lines = wrap(help, width.saturating_sub(indent).max(30)).into_iter();
        out += &format!("{name:name_w$}  {gpu:3}  {lights:lights_w$}  {}\n", lines.next().unwrap_or_default());
        for line in lines {
            out += &format!("{:indent$}{line}\n", "");
        }
    }
    out += "\n`--solver auto` (the hosts' default) picks one for the scene.\n\
            `volscatter solvers --json` lists every setting; docs/solvers/<name>.md says where each is accurate.";
    out
}

/// "all" when a solver handles every light type, else their names.
fn lights(handled: &[LightType]) -> String {
    if LightType::ALL.iter().all(|l| handled.contains(l)) {
        "all".into()
    } else {
        handled.iter().map(|l| l.name()).collect::<Vec<_>>().join(",")
    }
}

/// Words of `text` in lines of at most `width` characters (a longer word gets a line of its own).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in text.split_whitespace() {
        match lines.last_mut() {
            Some(line) if line.len() + 1 + word.len() <= width => {
                line.push(' ');
                line.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_lists_every_solver_within_its_width() {
        let t = table(registry::SOLVERS, 100);
        for name in registry::SOLVER_NAMES {
            assert!(t.lines().any(|l| l.starts_with(&format!("{name} "))), "{name} missing:\n{t}");
        }
        assert!(t.lines().all(|l| l.chars().count() <= 100), "a line over 100 characters:\n{t}");
        // Every word of every help is there (wrapped, not cut).
        let words: Vec<&str> = t.split_whitespace().collect();
        for s in registry::SOLVERS {
            assert!(s.help.split_whitespace().all(|w| words.contains(&w)), "{}'s help cut:\n{t}", s.name);
        }
    }

    #[test]
    fn wrap_keeps_words_whole() {
        assert_eq!(wrap("a bb ccc dddd", 6), ["a bb", "ccc", "dddd"]);
        assert_eq!(wrap("averylongword x", 4), ["averylongword", "x"]);
        assert!(wrap("", 10).is_empty());
    }
}
