//! How the workspace builds: the Python extension that `./ci.sh python` builds for its tests
//! reuses the crates the test job compiled.
//!
//! Cargo unifies the features of a dependency over the packages one build selects, so
//! `cargo test --workspace` and maturin's build of `rollest-python` alone can give a shared
//! crate two feature sets; each set is compiled apart, with every crate above it. When serde and
//! syn differed, CI compiled the workspace a second time. `python/Cargo.toml` turns on the
//! test build's features; this test says which crate differs when a change parts them again.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// Per package (`name vX.Y.Z`), the feature sets it is built with, from `cargo tree` over the
/// edges `edges` of the packages `selection` selects.
fn features(selection: &[&str], edges: &str) -> BTreeMap<String, BTreeSet<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the tests crate sits in the workspace");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .current_dir(root)
        .args(["tree", "--offline", "--locked", "-e", edges, "--prefix", "none", "-f", "{p}|{f}"])
        .args(selection)
        .output()
        .expect("cargo tree runs");
    assert!(output.status.success(), "cargo tree: {}", String::from_utf8_lossy(&output.stderr));
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&output.stdout).lines() {
        let line = line.trim_end_matches(" (*)");
        if let Some((package, features)) = line.split_once('|') {
            // A path dependency prints its folder after the version.
            let package = package.split(" (").next().unwrap_or(package).trim().to_owned();
            out.entry(package).or_default().insert(features.trim().to_owned());
        }
    }
    out
}

#[test]
fn the_python_extension_builds_every_shared_crate_with_the_test_builds_features() {
    let workspace = features(&["--workspace"], "normal,build,dev");
    let extension = features(&["-p", "rollest-python"], "normal,build");
    assert!(extension.len() > 50, "cargo tree listed {} packages of the extension", extension.len());
    // host-tools is built without its rigs for the extension on purpose (python/Cargo.toml):
    // only it and the extension itself are compiled again.
    let parted: Vec<String> = extension
        .iter()
        .filter(|(package, _)| !package.starts_with("host-tools "))
        .filter_map(|(package, sets)| {
            let test_build = workspace.get(package)?;
            (test_build != sets).then(|| format!("{package}: extension {sets:?}, test build {test_build:?}"))
        })
        .collect();
    assert!(parted.is_empty(), "crates the extension builds with other features:\n{}", parted.join("\n"));
}
