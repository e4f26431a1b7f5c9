//! Every registered solver in every harness: a solver added to the registry fails here, by
//! name, until each harness has it. The harnesses: the furnace and energy checks
//! (furnace.rs `expectation`), the ratchets against the converged references (an
//! `against_reference!` table whose first line names the solver, in its tests), and, checked
//! by their own crates' tests against the same registry: volscatter-gpu's `GPU_BACKENDS`
//! (shaders/src/backends_tests.rs), the extreme-value scenes (tests/src/extreme.rs), the C
//! ABI's cancel test (tests/tests/extreme_abi.rs `heavy_settings`) and the CLI's `solvers`
//! listing (plugin/tests/cli.rs).

use crate::solvers::registry::SOLVER_NAMES;

/// Registered names that are not solvers of their own: `auto` picks one of the others at a
/// measured preset (pipeline/auto/tests.rs checks that it does), each checked with its own
/// bounds.
fn picks(name: &str) -> bool {
    name == crate::pipeline::auto::NAME
}

/// Solvers without ratchets against the converged references, each with its reason.
fn no_ratchet_reason(name: &str) -> Option<&'static str> {
    match name {
        "reference" => Some("the fixtures are its converged solutions (pop/tests.rs `fixtures_match_current_reference` checks it still renders them)"),
        _ => None,
    }
}

/// The solvers named by `against_reference!` tables (`solver: "name";`, their first line) in
/// this crate's sources (testing.rs, which defines the macro, aside): each table's rows assert
/// that their solver has that name.
fn ratcheted_solvers() -> Vec<String> {
    let mut found = Vec::new();
    let mut dirs = vec![std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") && !path.ends_with("solvers/testing.rs") {
                let text = std::fs::read_to_string(&path).unwrap();
                let mut rest = text.as_str();
                while let Some(at) = rest.find("against_reference! {") {
                    rest = &rest[at + "against_reference! {".len()..];
                    let header = rest.trim_start();
                    if let Some(name) = header.strip_prefix("solver: \"").and_then(|h| h.split('"').next()) {
                        found.push(name.to_string());
                    }
                }
            }
        }
    }
    found
}

#[test]
fn every_registered_solver_is_in_every_harness() {
    let ratcheted = ratcheted_solvers();
    let mut missing = Vec::new();
    for &name in SOLVER_NAMES.iter().filter(|n| !picks(n)) {
        if super::furnace::expectation_of(name).is_none() {
            missing.push(format!("{name}: no furnace / energy tolerance (testing/furnace.rs `expectation_of`)"));
        }
        if !ratcheted.iter().any(|r| r == name) && no_ratchet_reason(name).is_none() {
            missing.push(format!("{name}: no `against_reference!` table (`solver: \"{name}\";`) in its tests"));
        }
    }
    for name in ratcheted.iter().filter(|r| !SOLVER_NAMES.contains(&r.as_str())) {
        missing.push(format!("an `against_reference!` table names `{name}`, which the registry does not have"));
    }
    assert!(missing.is_empty(), "solvers missing from harnesses:\n{}", missing.join("\n"));
}
