//! The layering of the workspace, checked over `cargo metadata`: the simulation and haptics
//! crates stay free of async runtimes, databases, web frameworks and recording formats, the
//! scoring crate of databases, object stores and servers, no crate depends on a crate above
//! it, only the command line depends on the benchmarks, and nothing on the peer engine of the
//! benchmarks.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use serde_json::Value;

/// Every package id reachable from `root` through normal (non-dev, non-build) dependencies,
/// not entering the packages `skipped`.
fn closure_without(
    resolve: &BTreeMap<String, Vec<String>>,
    root: &str,
    skipped: &BTreeSet<String>,
) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![root.to_owned()];
    while let Some(id) = stack.pop() {
        if !skipped.contains(&id) && seen.insert(id.clone()) {
            stack.extend(resolve.get(&id).into_iter().flatten().cloned());
        }
    }
    seen
}

fn metadata() -> (BTreeMap<String, Vec<String>>, BTreeMap<String, String>) {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--manifest-path"])
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml"))
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("metadata is JSON");
    let mut names = BTreeMap::new();
    for p in v["packages"].as_array().expect("packages") {
        names.insert(
            p["id"].as_str().expect("id").to_owned(),
            p["name"].as_str().expect("name").to_owned(),
        );
    }
    let mut resolve = BTreeMap::new();
    for node in v["resolve"]["nodes"].as_array().expect("nodes") {
        let id = node["id"].as_str().expect("id").to_owned();
        let deps = node["deps"]
            .as_array()
            .expect("deps")
            .iter()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .is_some_and(|k| k.iter().any(|k| k["kind"].is_null()))
            })
            .map(|d| d["pkg"].as_str().expect("pkg").to_owned())
            .collect();
        resolve.insert(id, deps);
    }
    (resolve, names)
}

fn reachable_names(crate_name: &str) -> BTreeSet<String> {
    reachable_names_without(crate_name, &[])
}

/// The names of the packages `crate_name` reaches other than through the packages `skipped`.
fn reachable_names_without(crate_name: &str, skipped: &[&str]) -> BTreeSet<String> {
    let (resolve, names) = metadata();
    let id_of = |name: &str| {
        names
            .iter()
            .filter(|(_, n)| *n == name)
            .map(|(id, _)| id.clone())
            .collect::<Vec<_>>()
    };
    let root = id_of(crate_name)
        .pop()
        .unwrap_or_else(|| panic!("{crate_name} is not in the workspace"));
    let skipped: BTreeSet<String> = skipped.iter().flat_map(|s| id_of(s)).collect();
    closure_without(&resolve, &root, &skipped)
        .into_iter()
        .map(|id| names[&id].clone())
        .collect()
}

const FORBIDDEN_BELOW_RECORDER: [&str; 7] =
    ["tokio", "sqlx", "axum", "mcap", "rerun", "re_sdk", "hyper"];

/// Which of `forbidden` are among `deps`.
fn forbidden_among<'a>(deps: &BTreeSet<String>, forbidden: &[&'a str]) -> Vec<&'a str> {
    forbidden
        .iter()
        .copied()
        .filter(|f| deps.contains(*f))
        .collect()
}

#[test]
fn sim_and_haptics_are_free_of_runtime_database_web_and_recording_crates() {
    for krate in ["cutlab-sim", "cutlab-haptics"] {
        let bad = forbidden_among(&reachable_names(krate), &FORBIDDEN_BELOW_RECORDER);
        assert!(
            bad.is_empty(),
            "{krate} depends (maybe indirectly) on {bad:?}"
        );
    }
}

/// What scoring must not need: a replay, a bench or another tool scores without a database,
/// an object store, an async runtime or a server. (The recorder's rerun SDK brings tokio and
/// hyper for its viewer connection: the check looks past rerun, not past the recorder.)
const FORBIDDEN_IN_SCORING: [&str; 9] = [
    "tokio",
    "sqlx",
    "object_store",
    "argon2",
    "axum",
    "hyper",
    "reqwest",
    "cutlab-assessor",
    "cutlab-station",
];

#[test]
fn scoring_is_free_of_database_store_and_server_crates() {
    let deps = reachable_names_without("cutlab-scoring", &["rerun"]);
    assert!(
        deps.contains("cutlab-sim") && deps.contains("parry3d-f64"),
        "the check sees scoring's real dependencies: {deps:?}"
    );
    let bad = forbidden_among(&deps, &FORBIDDEN_IN_SCORING);
    assert!(
        bad.is_empty(),
        "cutlab-scoring depends (maybe indirectly) on {bad:?}"
    );
    // the check is not vacuous: the store brings them, and so does rerun
    assert!(reachable_names("cutlab-assessor").contains("sqlx"));
    assert!(reachable_names("cutlab-scoring").contains("tokio"));
}

#[test]
fn no_crate_depends_on_a_crate_above_it() {
    let layers = [
        "cutlab-sim",
        "cutlab-haptics",
        "cutlab-recorder",
        "cutlab-scoring",
        "cutlab-assessor",
        "cutlab-station",
        "cutlab-dashboard",
        "cutlab-bench",
        "cutlab",
    ];
    for (i, krate) in layers.iter().enumerate() {
        let deps = reachable_names(krate);
        for above in &layers[i + 1..] {
            assert!(!deps.contains(*above), "{krate} must not depend on {above}");
        }
    }
}

#[test]
fn only_the_command_line_depends_on_the_benchmarks() {
    // `cutlab-bench` may depend on every library crate; of the workspace's crates, only the
    // command line (`cutlab bench ...`) may depend on it.
    let (_, names) = metadata();
    let crates: BTreeSet<&String> = names
        .values()
        .filter(|n| n.starts_with("cutlab-") && *n != "cutlab-bench")
        .collect();
    assert!(
        crates.len() >= 5,
        "the library crates are in the metadata: {crates:?}"
    );
    for krate in crates {
        assert!(
            !reachable_names(krate).contains("cutlab-bench"),
            "{krate} must not depend on cutlab-bench"
        );
    }
    assert!(reachable_names("cutlab").contains("cutlab-bench"));
}

#[test]
fn the_check_sees_real_dependencies() {
    // Guards the test itself: the sim closure does contain nalgebra.
    assert!(reachable_names("cutlab-sim").contains("nalgebra"));
}

#[test]
fn the_peer_engine_is_a_bench_only_dependency() {
    // Rapier is compared with in `bench/benches/peer` only (a dev-dependency of
    // `cutlab-bench`): no crate, the benchmarks' and the command line's included, may depend
    // on it. (It is in the metadata, as a dev-dependency: the check below is not vacuous.)
    let (_, names) = metadata();
    assert!(
        names.values().any(|n| n == "rapier3d-f64"),
        "rapier3d-f64 is in the workspace's metadata"
    );
    for krate in [
        "cutlab-sim",
        "cutlab-haptics",
        "cutlab-recorder",
        "cutlab-scoring",
        "cutlab-assessor",
        "cutlab-station",
        "cutlab-dashboard",
        "cutlab-bench",
        "cutlab",
    ] {
        let rapier: Vec<String> = reachable_names(krate)
            .into_iter()
            .filter(|d| d.starts_with("rapier"))
            .collect();
        assert!(rapier.is_empty(), "{krate} depends on {rapier:?}");
    }
}

#[test]
fn no_crate_re_exports_another() {
    // A crate that uses another declares it (issue 43): a re-exported crate (`pub use
    // cutlab_haptics as haptics`) let the assessor use the haptics crate without saying so.
    fn rust_files(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("source folder").flatten() {
            let path = entry.path();
            if path.is_dir() {
                rust_files(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for krate in [
        "sim",
        "haptics",
        "recorder",
        "scoring",
        "assessor",
        "station",
        "web-dashboard",
        "bench",
        ".",
    ] {
        rust_files(&root.join(krate).join("src"), &mut files);
    }
    assert!(files.len() > 50, "the sources are found: {}", files.len());
    let mut found = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("source");
        for line in text.lines() {
            let words: Vec<&str> = line
                .trim()
                .trim_end_matches(';')
                .split_whitespace()
                .collect();
            let whole_crate = match words.as_slice() {
                ["pub", "use", path] | ["pub", "use", path, "as", _] => !path.contains("::"),
                _ => false,
            };
            if whole_crate && words[2].starts_with("cutlab_") {
                found.push(format!("{}: {}", file.display(), line.trim()));
            }
        }
    }
    assert!(found.is_empty(), "crates re-exported: {found:#?}");
}

/// The modules of `cutlab-scoring` each imports outside its tests and comments
/// (`crate::<module>` paths), by module.
fn scoring_module_imports() -> BTreeMap<String, BTreeSet<String>> {
    fn walk(dir: &std::path::Path, root: &std::path::Path, out: &mut Vec<(String, String)>) {
        for entry in std::fs::read_dir(dir).expect("scoring's sources").flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, root, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let rel = path.strip_prefix(root).expect("under src");
                let first = rel.components().next().expect("a path");
                let module = first
                    .as_os_str()
                    .to_string_lossy()
                    .trim_end_matches(".rs")
                    .to_owned();
                let text = std::fs::read_to_string(&path).expect("source");
                let code = text
                    .split("#[cfg(test)]\nmod tests")
                    .next()
                    .unwrap_or_default();
                out.push((module, code.to_owned()));
            }
        }
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scoring/src");
    let mut files = Vec::new();
    walk(&root, &root, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, code) in files {
        let entry = graph.entry(module.clone()).or_default();
        for line in code.lines().filter(|l| !l.trim_start().starts_with("//")) {
            for (i, _) in line.match_indices("crate::") {
                let name: String = line[i + 7..]
                    .chars()
                    .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                    .collect();
                if !name.is_empty() && name != module {
                    entry.insert(name);
                }
            }
        }
    }
    graph
}

/// A circle among `graph`'s nodes, if there is one.
fn a_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| n == node) {
            let mut circle = path[at..].to_vec();
            circle.push(node.to_owned());
            return Some(circle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_owned());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(next, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

#[test]
fn scorings_modules_import_each_other_in_no_circle() {
    // metrics below the exercise kinds: a kind picks metrics, no metric knows a kind
    let graph = scoring_module_imports();
    assert!(
        graph.get("exercise").is_some_and(|m| m.contains("metrics")),
        "the check reads the imports: {graph:?}"
    );
    assert!(
        !graph["metrics"].contains("exercise"),
        "metrics import the exercise kinds: {:?}",
        graph["metrics"]
    );
    assert_eq!(a_circle(&graph), None, "{graph:#?}");
    // and the search finds one where there is one
    let mut with_circle = graph.clone();
    with_circle
        .entry("metrics".into())
        .or_default()
        .insert("exercise".into());
    assert!(a_circle(&with_circle).is_some());
}
