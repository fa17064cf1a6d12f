//! `docs/design.md` §2 against the workspace as Cargo sees it: the "Crates" table has a row for
//! every crate of the workspace, and each row's "uses" column names exactly the workspace crates
//! that crate depends on (normal dependencies; dev-dependencies are the tests' business). A
//! crate or a dependency edge added without its row fails here, saying which.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace")
        .to_path_buf()
}

/// The names between backticks in `text`.
fn backticked(text: &str) -> BTreeSet<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect()
}

/// The "Crates" table of design.md §2: each row's crate and the crates its "uses" column names.
/// Rows whose first cell is not one backticked name (`python/` is not a crate) are skipped.
fn design_table(design: &str) -> BTreeMap<String, BTreeSet<String>> {
    let section = design
        .split_once("### Crates")
        .expect("docs/design.md has a \"### Crates\" section")
        .1;
    let mut rows = BTreeMap::new();
    for line in section.lines().skip_while(|l| !l.starts_with('|')) {
        if !line.starts_with('|') {
            break;
        }
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        let [name, _what, uses] = cells[..] else {
            panic!("docs/design.md §2: a row of the crates table without 3 cells: {line}");
        };
        let Some(name) = name.strip_prefix('`').and_then(|n| n.strip_suffix('`')) else {
            continue;
        };
        if name.ends_with('/') {
            continue;
        }
        rows.insert(name.to_owned(), backticked(uses));
    }
    rows
}

/// Every workspace crate and the workspace crates it depends on, as `cargo metadata` has them.
fn workspace_graph() -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metadata: Value = serde_json::from_slice(&out.stdout).expect("cargo metadata's JSON");
    let packages = metadata["packages"].as_array().expect("packages");
    let names: BTreeSet<String> = packages
        .iter()
        .filter_map(|p| p["name"].as_str().map(str::to_owned))
        .collect();
    packages
        .iter()
        .map(|p| {
            let uses = p["dependencies"]
                .as_array()
                .expect("dependencies")
                .iter()
                .filter(|d| d["kind"].is_null())
                .filter_map(|d| d["name"].as_str())
                .filter(|d| names.contains(*d))
                .map(str::to_owned)
                .collect();
            (p["name"].as_str().expect("a name").to_owned(), uses)
        })
        .collect()
}

#[test]
fn the_design_lists_every_crate_with_the_crates_it_uses() {
    let design = std::fs::read_to_string(root().join("docs/design.md")).expect("docs/design.md");
    let table = design_table(&design);
    let graph = workspace_graph();
    assert!(
        graph.len() > 5,
        "cargo metadata listed too few crates: {graph:?}"
    );
    let mut problems = Vec::new();
    for (name, uses) in &graph {
        match table.get(name) {
            None => problems.push(format!("crate {name} has no row")),
            Some(listed) if listed != uses => {
                problems.push(format!("{name} uses {uses:?}, the row says {listed:?}"))
            }
            Some(_) => {}
        }
    }
    for name in table.keys().filter(|n| !graph.contains_key(*n)) {
        problems.push(format!("a row for {name}, which is not a workspace crate"));
    }
    assert!(
        problems.is_empty(),
        "docs/design.md §2, \"Crates\", does not match cargo metadata:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_table_reader_reads_names_and_uses() {
    let doc = "### Crates\n\n| crate | what | uses |\n|---|---|---|\n\
               | `a` | the `x` thing | — |\n| `b` | b | `a`, `c` |\n\
               | `py/` (not a crate) | p | the binary |\n| `t` | t | the binaries; `a` |\n\nafter\n";
    let table = design_table(doc);
    let set = |names: &[&str]| {
        names
            .iter()
            .map(|n| (*n).to_owned())
            .collect::<BTreeSet<_>>()
    };
    assert_eq!(table.len(), 3);
    assert_eq!(table["a"], set(&[]));
    assert_eq!(table["b"], set(&["a", "c"]));
    assert_eq!(table["t"], set(&["a"]));
}
