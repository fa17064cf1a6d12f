//! The docs' results against `docs/manifest.json`: every table, JSON file and picture that the
//! Markdown docs link under `docs/img/`, `docs/results/` and `docs/bench/` is recorded there
//! (the commands that made it, the commit, the date), every recorded file exists, and
//! `docs/figures.toml`, the entries `scripts/figures.py` runs to remake them, names the same
//! files as the manifest. Nothing is run: the files are read as they are.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use serde_json::Value;

/// Where the files the docs show live; a linked file there must be in the manifest.
const RESULT_DIRS: [&str; 3] = ["docs/img/", "docs/results/", "docs/bench/"];

/// The kinds of file checked (a link to a directory or to a scenario is not a result).
const RESULT_EXTENSIONS: [&str; 5] = ["png", "gif", "json", "csv", "md"];

/// The Markdown files outside `docs/` whose links are checked; every `docs/**/*.md` is too.
const TOP_DOCS: [&str; 3] = ["README.md", "CONTRIBUTING.md", "scenarios/README.md"];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace")
        .to_path_buf()
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The manifest's records, by repository path.
fn manifest() -> BTreeMap<String, Value> {
    let manifest: Value = serde_json::from_str(&read("docs/manifest.json"))
        .unwrap_or_else(|e| panic!("docs/manifest.json: {e}"));
    let Some(Value::Object(outputs)) = manifest.get("outputs") else {
        panic!("docs/manifest.json has no \"outputs\" object");
    };
    outputs.clone().into_iter().collect()
}

/// The entries of `docs/figures.toml`: each name and the files its `copy` writes.
fn figures() -> BTreeMap<String, Vec<String>> {
    let figures: toml::Table = read("docs/figures.toml")
        .parse()
        .unwrap_or_else(|e| panic!("docs/figures.toml: {e}"));
    let entries = figures
        .get("figure")
        .and_then(toml::Value::as_array)
        .expect("docs/figures.toml has [[figure]] entries");
    let mut by_name = BTreeMap::new();
    for entry in entries {
        let name = entry
            .get("name")
            .and_then(toml::Value::as_str)
            .unwrap_or_else(|| panic!("docs/figures.toml: an entry without a name: {entry}"));
        let outputs: Vec<String> = entry
            .get("copy")
            .and_then(toml::Value::as_array)
            .unwrap_or_else(|| panic!("docs/figures.toml: entry {name} has no copy list"))
            .iter()
            .map(|copy| {
                copy.get("to")
                    .and_then(toml::Value::as_str)
                    .unwrap_or_else(|| panic!("docs/figures.toml: entry {name}: a copy without to"))
                    .to_owned()
            })
            .collect();
        assert!(
            by_name.insert(name.to_owned(), outputs).is_none(),
            "docs/figures.toml: two entries are named {name}"
        );
    }
    by_name
}

/// The entry of `docs/figures.toml` that writes `path`, if any.
fn entry_writing<'a>(figures: &'a BTreeMap<String, Vec<String>>, path: &str) -> Option<&'a str> {
    figures
        .iter()
        .find(|(_, outputs)| outputs.iter().any(|o| o == path))
        .map(|(name, _)| name.as_str())
}

/// What to do about `path`: run the entry that makes it, or add one.
fn remedy(figures: &BTreeMap<String, Vec<String>>, path: &str) -> String {
    match entry_writing(figures, path) {
        Some(name) => format!("run `python3 scripts/figures.py --only {name}`, which records it"),
        None => "add an entry that makes it to docs/figures.toml and run `python3 \
                 scripts/figures.py --only NAME`; a hand-written doc is recorded as \
                 {\"kind\": \"analysis\"}"
            .to_owned(),
    }
}

/// The Markdown files whose links are checked, relative to the root.
fn markdown_docs() -> Vec<String> {
    fn walk(dir: &Path, root: &Path, found: &mut Vec<String>) {
        let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                walk(&path, root, found);
            } else if path.extension().is_some_and(|e| e == "md") {
                let relative = path.strip_prefix(root).expect("under the root");
                found.push(relative.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    let root = root();
    let mut docs: Vec<String> = TOP_DOCS.iter().map(|d| (*d).to_owned()).collect();
    walk(&root.join("docs"), &root, &mut docs);
    docs.sort();
    docs
}

/// The targets of the links and images (`[text](target)`, `![alt](target)`) of a Markdown
/// text, outside fenced code blocks.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    let mut in_fence = false;
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            rest = &rest[at + 2..];
            let Some(end) = rest.find(')') else { break };
            // `(target "title")` or `(<target with spaces>)`.
            let inside = &rest[..end];
            let target = match inside.strip_prefix('<') {
                Some(quoted) => quoted.split('>').next(),
                None => inside.split_whitespace().next(),
            };
            targets.push(target.unwrap_or("").to_owned());
            rest = &rest[end..];
        }
    }
    targets
}

/// A link's target as a path from the root, or `None` for a URL, an anchor in the same
/// file or a path that leaves the repository.
fn resolve(doc: &str, target: &str) -> Option<String> {
    if target.contains("://") || target.starts_with("mailto:") {
        return None;
    }
    let path = target.split(['#', '?']).next().unwrap_or("");
    if path.is_empty() {
        return None;
    }
    let base = Path::new(doc).parent().unwrap_or(Path::new(""));
    let mut parts: Vec<String> = Vec::new();
    for component in base.join(path).components() {
        match component {
            Component::Normal(part) => parts.push(part.to_string_lossy().into_owned()),
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::CurDir => {}
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(parts.join("/"))
}

/// Whether a linked path is a result the manifest must record.
fn is_result(path: &str) -> bool {
    RESULT_DIRS.iter().any(|dir| path.starts_with(dir))
        && Path::new(path)
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| RESULT_EXTENSIONS.contains(&e))
}

fn is_analysis(record: &Value) -> bool {
    record.get("kind").and_then(Value::as_str) == Some("analysis")
}

fn pending(record: &Value) -> bool {
    record.get("pending").is_some()
}

fn fail_with(problems: &[String]) {
    assert!(
        problems.is_empty(),
        "{} problem(s) with the docs' results (docs/manifest.json, CONTRIBUTING.md \
         \"Figures\"):\n- {}",
        problems.len(),
        problems.join("\n- ")
    );
}

#[test]
fn every_result_the_docs_link_is_in_the_manifest() {
    let manifest = manifest();
    let figures = figures();
    // A set: a doc that links a file twice is told once.
    let mut problems = BTreeSet::new();
    let mut checked = 0;
    for doc in markdown_docs() {
        for target in link_targets(&read(&doc)) {
            let Some(path) = resolve(&doc, &target) else {
                continue;
            };
            if !is_result(&path) {
                continue;
            }
            checked += 1;
            match manifest.get(&path) {
                None => {
                    problems.insert(format!(
                        "{doc} links ({target}), {path}, which docs/manifest.json does not \
                         record: {}",
                        remedy(&figures, &path)
                    ));
                }
                Some(record) if pending(record) => {
                    problems.insert(format!(
                        "{doc} links ({target}), {path}, which was never made: {}",
                        remedy(&figures, &path)
                    ));
                }
                Some(_) => {}
            }
        }
    }
    assert!(
        checked > 0,
        "no link to a result found: is the link parser broken?"
    );
    fail_with(&problems.into_iter().collect::<Vec<_>>());
}

#[test]
fn every_file_the_manifest_records_exists() {
    let figures = figures();
    let mut problems = Vec::new();
    for (path, record) in &manifest() {
        let exists = root().join(path).is_file();
        if is_analysis(record) {
            if !exists {
                problems.push(format!(
                    "docs/manifest.json records the analysis {path}, which does not exist: \
                     remove its record"
                ));
            }
        } else if pending(record) {
            if exists {
                problems.push(format!(
                    "{path} exists, but docs/manifest.json says it was never made: {}",
                    remedy(&figures, path)
                ));
            }
        } else {
            if !exists {
                problems.push(format!(
                    "docs/manifest.json records {path}, which does not exist: {}, or remove \
                     its record",
                    remedy(&figures, path)
                ));
            }
            let has_commands = record
                .get("commands")
                .and_then(Value::as_array)
                .is_some_and(|c| !c.is_empty() && c.iter().all(Value::is_string));
            let has_fields = ["entry", "commit", "date"]
                .iter()
                .all(|key| record.get(*key).is_some_and(Value::is_string))
                && record.get("remade").is_some_and(Value::is_boolean);
            if !has_commands || !has_fields {
                problems.push(format!(
                    "docs/manifest.json: {path} needs \"entry\", \"commands\", \"commit\", \
                     \"date\" and \"remade\": {}",
                    remedy(&figures, path)
                ));
            }
        }
    }
    fail_with(&problems);
}

#[test]
fn the_figures_list_and_the_manifest_name_the_same_files() {
    let manifest = manifest();
    let figures = figures();
    let mut problems = Vec::new();
    let mut written = BTreeSet::new();
    for (name, outputs) in &figures {
        for path in outputs {
            if !written.insert(path.as_str()) {
                problems.push(format!(
                    "docs/figures.toml: {path} is written by more than one entry"
                ));
            }
            let recorded_by = manifest
                .get(path)
                .and_then(|record| record.get("entry"))
                .and_then(Value::as_str);
            if recorded_by != Some(name) || manifest.get(path).is_some_and(is_analysis) {
                problems.push(format!(
                    "docs/figures.toml: entry {name} writes {path}, which docs/manifest.json \
                     does not record as entry {name}'s: run `python3 scripts/figures.py --only \
                     {name}`"
                ));
            }
        }
    }
    for (path, record) in &manifest {
        let entry = record.get("entry").and_then(Value::as_str);
        if is_analysis(record) {
            if let Some(entry) = entry
                && !figures.contains_key(entry)
            {
                problems.push(format!(
                    "docs/manifest.json: the analysis {path} names entry {entry}, which \
                     docs/figures.toml does not have"
                ));
            }
            continue;
        }
        let listed = entry
            .and_then(|entry| figures.get(entry))
            .is_some_and(|outputs| outputs.iter().any(|o| o == path));
        if !listed {
            problems.push(format!(
                "docs/manifest.json: {path} is recorded as made by entry {}, which does not \
                 write it in docs/figures.toml: add it to that entry's copy list or remove \
                 its record",
                entry.unwrap_or("(none)")
            ));
        }
    }
    fail_with(&problems);
}

#[test]
fn links_are_read_as_markdown_writes_them() {
    let text = "See [`table.md`](table.md), ![a picture](../img/a.png \"title\") and \
                [a section](#results) or [the web](https://example.com/x.png).\n\
                ```sh\nls [x](ignored.png)\n```\n[b](<b c.json>)";
    let targets = link_targets(text);
    assert_eq!(
        targets,
        [
            "table.md",
            "../img/a.png",
            "#results",
            "https://example.com/x.png",
            "b c.json"
        ]
    );
    let doc = "docs/results/README.md";
    assert_eq!(
        resolve(doc, "../img/a.png#top").as_deref(),
        Some("docs/img/a.png")
    );
    assert_eq!(
        resolve(doc, "table.md").as_deref(),
        Some("docs/results/table.md")
    );
    assert_eq!(resolve(doc, "#results"), None);
    assert_eq!(resolve(doc, "https://example.com/x.png"), None);
    assert_eq!(resolve(doc, "../../../outside.md"), None);
    assert!(is_result("docs/bench/scale.png"));
    assert!(!is_result("docs/foxglove/setfleet-layout.json"));
    assert!(!is_result("docs/results/"));
}
