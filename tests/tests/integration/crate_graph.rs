//! The crates' dependency graph, dev-dependencies included, as docs/ARCHITECTURE.md draws
//! it: the simulator (`envs`) depends on no other crate of the workspace, and no chain of
//! dependencies runs back to where it started.

use std::collections::BTreeMap;

/// The workspace crates each crate's manifest names, in `[dependencies]`,
/// `[dev-dependencies]` or `[build-dependencies]`.
fn workspace_edges() -> BTreeMap<&'static str, Vec<String>> {
    const CRATES: [&str; 7] = ["tensor", "nn", "envs", "models", "rl", "tests", "python"];
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    CRATES
        .iter()
        .map(|&c| {
            let path = format!("{root}/{c}/Cargo.toml");
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
            let manifest: toml::Table = toml::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
            let mut deps = Vec::new();
            for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
                if let Some(t) = manifest.get(section).and_then(|v| v.as_table()) {
                    deps.extend(t.keys().filter(|k| CRATES.contains(&k.as_str())).cloned());
                }
            }
            (c, deps)
        })
        .collect()
}

#[test]
fn the_simulator_depends_on_no_other_workspace_crate() {
    assert_eq!(workspace_edges()["envs"], Vec::<String>::new());
}

#[test]
fn no_dependency_cycle_even_through_dev_dependencies() {
    let edges = workspace_edges();
    // Depth-first search from every crate: a crate met again on the current path is a cycle.
    fn visit<'a>(c: &'a str, edges: &'a BTreeMap<&'static str, Vec<String>>, path: &mut Vec<&'a str>) {
        assert!(!path.contains(&c), "dependency cycle: {} -> {c}", path.join(" -> "));
        path.push(c);
        for d in edges.get(c).into_iter().flatten() {
            visit(d, edges, path);
        }
        path.pop();
    }
    for c in edges.keys() {
        visit(c, &edges, &mut Vec::new());
    }
    // The models read the environment's observation layout.
    assert!(edges["models"].iter().any(|d| d == "envs"));
}

/// `docs/ARCHITECTURE.md` names this layout and stays a map: under 15 KB.
#[test]
fn the_architecture_map_stays_under_15_kb_and_names_the_layout() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/ARCHITECTURE.md");
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.len() < 15_000, "{path}: {} bytes", text.len());
    for name in ["envs::layout", "envs/src/forward.rs", "ppo::loss", "minibatch", "tests/integration/"] {
        assert!(text.contains(name), "{path} does not name {name}");
    }
}
