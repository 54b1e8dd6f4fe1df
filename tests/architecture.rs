//! docs/architecture.md's table of who depends on whom is the crate graph: every grin
//! crate's normal dependencies on other grin crates (from `cargo metadata`) are exactly
//! the ones its row names, so an edge added or dropped in a Cargo.toml fails here until
//! the doc draws it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// The workspace's crates and their normal (not dev or build) dependencies among them.
fn crate_graph(root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root)
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("metadata is JSON");
    let packages = meta["packages"].as_array().expect("packages");
    let members: BTreeSet<String> = packages
        .iter()
        .map(|p| p["name"].as_str().expect("name").to_owned())
        .collect();
    packages
        .iter()
        .map(|p| {
            let deps = p["dependencies"]
                .as_array()
                .expect("dependencies")
                .iter()
                .filter(|d| d["kind"].is_null())
                .map(|d| d["name"].as_str().expect("dep name").to_owned())
                .filter(|d| members.contains(d))
                .collect();
            (p["name"].as_str().expect("name").to_owned(), deps)
        })
        .collect()
}

/// The doc's rows `| crate | dependencies | why |` under "Who depends on whom": `-` for
/// none; `all` (`None`: the binary, which may use any other crate).
fn documented(doc: &str, crates: &BTreeSet<String>) -> BTreeMap<String, Option<BTreeSet<String>>> {
    let section = doc
        .split("## Who depends on whom")
        .nth(1)
        .expect("docs/architecture.md has a 'Who depends on whom' section");
    section
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let name = *cells.get(1)?;
            crates.contains(name).then(|| {
                let deps = match cells[2] {
                    "-" => Some(BTreeSet::new()),
                    "all" => None,
                    list => Some(list.split(',').map(|d| d.trim().to_owned()).collect()),
                };
                (name.to_owned(), deps)
            })
        })
        .collect()
}

#[test]
fn the_architecture_doc_draws_every_crate_edge_and_no_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let graph = crate_graph(&root);
    let doc = std::fs::read_to_string(root.join("docs/architecture.md")).expect("read the doc");
    let crates: BTreeSet<String> = graph.keys().cloned().collect();
    let drawn = documented(&doc, &crates);
    let mut wrong = Vec::new();
    for (name, deps) in &graph {
        let Some(row) = drawn.get(name) else {
            wrong.push(format!("{name}: no row in the table"));
            continue;
        };
        let Some(row) = row else {
            continue; // `all`
        };
        for d in deps.difference(row) {
            wrong.push(format!("{name} depends on {d}: the doc does not draw it"));
        }
        for d in row.difference(deps) {
            wrong.push(format!(
                "{name}: the doc draws {d}, Cargo.toml has no such dependency"
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "docs/architecture.md vs cargo metadata:\n{}",
        wrong.join("\n")
    );
    assert!(
        drawn.len() >= 10,
        "only {} rows read: {drawn:?}",
        drawn.len()
    );
}
