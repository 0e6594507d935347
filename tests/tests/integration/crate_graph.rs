//! The crates' dependency graph, dev-dependencies included, as docs/ARCHITECTURE.md draws
//! it: the simulator (`envs`) depends on no other crate of the workspace, and no chain of
//! dependencies runs back to where it started. Inside `rl`, the module directions it states
//! too: `rl::mappo` never uses `rl::app`, and the bottom layer of `rl::app` (the run
//! directory's files) uses nothing of `app` above it; both read from the `crate::` and
//! `super::` paths in `rl/src`'s code, unit tests included.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

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

/// The bottom layer of `rl::app`: the files of a run directory (their names and layout,
/// lock, morphology copies, builds, metrics columns) and reading them back, with the unit
/// tests' helper. Its modules use no other module of `app`.
const APP_BOTTOM: [&str; 8] =
    ["build_info", "lock", "metrics", "morphology", "names", "record", "run_dir", "test_util"];

/// `rl/src`.
fn rl_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../rl/src")
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// The module path of a file of `rl/src`: `app/record/rows.rs` -> `[app, record, rows]`,
/// `app/record/mod.rs` -> `[app, record]`, `lib.rs` -> `[]`.
fn module_of(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(rl_src()).unwrap();
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if !matches!(stem, "mod" | "lib" | "main") {
        parts.push(stem.to_string());
    }
    parts
}

/// A file's text without its comments (`//` to the end of the line, doc comments included).
fn code_of(text: &str) -> String {
    text.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// The paths that the path starting at byte `at` of `code` names, groups expanded:
/// `app::{lock::RunLock, plot}` -> `[app, lock, RunLock]`, `[app, plot]`.
fn paths_at(code: &[u8], at: &mut usize) -> Vec<Vec<String>> {
    let skip_space = |at: &mut usize| {
        while *at < code.len() && code[*at].is_ascii_whitespace() {
            *at += 1;
        }
    };
    let mut prefix = Vec::new();
    loop {
        skip_space(at);
        if *at < code.len() && code[*at] == b'{' {
            *at += 1;
            let mut out = Vec::new();
            loop {
                skip_space(at);
                if *at >= code.len() || code[*at] == b'}' {
                    *at += 1;
                    break;
                }
                for tail in paths_at(code, at) {
                    out.push(prefix.iter().cloned().chain(tail).collect());
                }
                skip_space(at);
                if *at < code.len() && code[*at] == b',' {
                    *at += 1;
                }
            }
            return out;
        }
        let start = *at;
        while *at < code.len() && (code[*at].is_ascii_alphanumeric() || matches!(code[*at], b'_' | b'*')) {
            *at += 1;
        }
        if start == *at {
            return vec![prefix];
        }
        prefix.push(String::from_utf8_lossy(&code[start..*at]).into_owned());
        if code[*at..].starts_with(b"::") {
            *at += 2;
        } else {
            // `x as y`, `;`, `(`, ...: the path ends here.
            return vec![prefix];
        }
    }
}

/// Every `crate::` and `super::` path in `code`, groups expanded, as written.
fn paths_in(code: &str) -> Vec<Vec<String>> {
    let bytes = code.as_bytes();
    let mut out = Vec::new();
    for start in ["crate::", "super::"] {
        for (i, _) in code.match_indices(start) {
            if i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || matches!(bytes[i - 1], b'_' | b':')) {
                continue;
            }
            let mut at = i;
            out.extend(paths_at(bytes, &mut at));
        }
    }
    out
}

/// The module paths from the crate root that `path`, written in a file of module `module`,
/// may name: `crate::a::b` names `[a, b]`; `super::` is taken both at the file's level and
/// one module deeper (inside its `mod tests`), so that neither way round slips through.
fn resolved(module: &[String], path: &[String]) -> Vec<Vec<String>> {
    let supers = path.iter().take_while(|s| *s == "super").count();
    if path.first().is_some_and(|s| s == "crate") {
        return vec![path[1..].to_vec()];
    }
    let mut out = Vec::new();
    for depth in [module.len(), module.len() + 1] {
        if supers <= depth && supers > 0 {
            let base = &module[..(depth - supers).min(module.len())];
            out.push(base.iter().cloned().chain(path[supers..].iter().cloned()).collect());
        }
    }
    out
}

/// The names `rl`'s root re-exports (`pub use app::run_dir::RunDir;` in `lib.rs`) with the
/// module path each comes from: `RunDir` -> `[app, run_dir]`.
fn root_reexports() -> BTreeMap<String, Vec<String>> {
    let path = rl_src().join("lib.rs");
    let code = code_of(&std::fs::read_to_string(&path).unwrap());
    let mut out = BTreeMap::new();
    for (i, _) in code.match_indices("pub use ") {
        let mut at = i + "pub use ".len();
        for p in paths_at(code.as_bytes(), &mut at) {
            if let Some((name, module)) = p.split_last() {
                out.insert(name.clone(), module.to_vec());
            }
        }
    }
    assert!(out.get("RunDir").is_some_and(|m| m == &["app", "run_dir"]), "{}: {out:?}", path.display());
    out
}

/// A file of `rl/src`, its module path and the module paths it names.
type References = Vec<(PathBuf, Vec<String>, Vec<Vec<String>>)>;

/// Every module path (from `rl`'s root) that each file of `rl/src` names in its code, with
/// the crate root's re-exports (`crate::RunDir`) traced to where they come from.
fn rl_module_references() -> References {
    let reexports = root_reexports();
    rust_files(&rl_src())
        .into_iter()
        .map(|file| {
            let module = module_of(&file);
            let code = code_of(&std::fs::read_to_string(&file).unwrap());
            let mut named: Vec<Vec<String>> = Vec::new();
            for p in paths_in(&code) {
                for mut r in resolved(&module, &p) {
                    if let Some(from) = r.first().and_then(|n| reexports.get(n)) {
                        r.splice(0..1, from.iter().cloned());
                    }
                    named.push(r);
                }
            }
            (file, module, named)
        })
        .collect()
}

/// The paths of `references` that name a module of `app` for which `bad` holds, one line each.
fn offending(
    references: &References,
    in_scope: impl Fn(&[String]) -> bool,
    bad: impl Fn(&[String]) -> bool,
) -> Vec<String> {
    let mut out = BTreeSet::new();
    for (file, module, named) in references {
        if in_scope(module) {
            for n in named.iter().filter(|n| bad(n)) {
                let rel = file.strip_prefix(rl_src()).unwrap_or(file);
                out.insert(format!("rl/src/{} names crate::{}", rel.display(), n.join("::")));
            }
        }
    }
    out.into_iter().collect()
}

/// docs/ARCHITECTURE.md: `rl::app` uses `rl::mappo`, never the reverse (configuration files
/// are read by `mappo` itself, and its tests on the presets are `rl`'s integration tests).
#[test]
fn rl_mappo_never_names_rl_app() {
    let references = rl_module_references();
    let in_mappo = |m: &[String]| m.first().is_some_and(|s| s == "mappo");
    let names_app = |n: &[String]| n.first().is_some_and(|s| s == "app");
    assert!(offending(&references, in_mappo, |_| true).len() > 10, "no references found: is the parser broken?");
    let bad = offending(&references, in_mappo, names_app);
    assert!(bad.is_empty(), "rl::mappo must not use rl::app:\n{}", bad.join("\n"));
}

/// docs/ARCHITECTURE.md: the bottom layer of `rl::app` ([`APP_BOTTOM`]) uses no module of
/// `app` outside it.
#[test]
fn rl_apps_bottom_layer_names_nothing_of_app_above_it() {
    let app_modules: BTreeSet<String> = std::fs::read_dir(rl_src().join("app"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .filter(|m| m != "mod")
        .collect();
    for m in APP_BOTTOM {
        assert!(app_modules.contains(m), "rl/src/app has no module {m}");
    }
    let references = rl_module_references();
    let in_bottom = |m: &[String]| m.len() >= 2 && m[0] == "app" && APP_BOTTOM.contains(&m[1].as_str());
    let above = |n: &[String]| {
        n.len() >= 2 && n[0] == "app" && app_modules.contains(&n[1]) && !APP_BOTTOM.contains(&n[1].as_str())
    };
    let bad = offending(&references, in_bottom, above);
    assert!(bad.is_empty(), "rl::app's bottom layer must not use the modules above it:\n{}", bad.join("\n"));
    // The layer does use itself: the parser sees its references.
    let within = |n: &[String]| n.len() >= 2 && n[0] == "app" && APP_BOTTOM.contains(&n[1].as_str());
    assert!(offending(&references, in_bottom, within).len() >= 5, "no references found: is the parser broken?");
}
