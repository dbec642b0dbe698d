//! The tree stands on its own: its contracts are in `docs/spec/`, and no code or document
//! sends a reader to a path outside the repository (a clone has nothing beside it).

use std::path::{Path, PathBuf};

/// The workspace root (this crate sits one level below it).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("the tests crate sits in the workspace").to_path_buf()
}

/// Every source and document file of the tree with its text (build output, version control
/// and virtual environments left out; files that are not UTF-8 skipped).
fn texts() -> Vec<(PathBuf, String)> {
    const SKIP: [&str; 6] = ["target", ".git", "out", "node_modules", ".venv", "__pycache__"];
    const EXTENSIONS: [&str; 10] = ["rs", "md", "py", "sh", "toml", "h", "c", "txt", "ipynb", "cfg"];
    let mut out = Vec::new();
    let mut stack = vec![root()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("a directory entry").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if path.is_dir() {
                if !SKIP.contains(&name) {
                    stack.push(path);
                }
            } else if path.extension().and_then(|e| e.to_str()).is_some_and(|e| EXTENSIONS.contains(&e))
                && let Ok(text) = std::fs::read_to_string(&path)
            {
                out.push((path, text));
            }
        }
    }
    out
}

#[test]
fn no_file_refers_to_the_shared_folder_outside_the_repository() {
    // Spelled in parts, so that this file does not match itself.
    let shared = "shared";
    let outside: Vec<String> = ["spec", "research", "design", "seed"]
        .iter()
        .map(|dir| format!("{shared}/{dir}"))
        .chain(std::iter::once(format!("../{shared}")))
        .collect();
    let mut found = Vec::new();
    for (path, text) in texts() {
        for (line_no, line) in text.lines().enumerate() {
            if outside.iter().any(|needle| line.contains(needle.as_str())) {
                found.push(format!("{}:{}: {}", path.display(), line_no + 1, line.trim()));
            }
        }
    }
    assert!(found.is_empty(), "paths outside the repository:\n{}", found.join("\n"));
}

#[test]
fn every_contract_a_file_names_is_in_docs_spec() {
    let spec = root().join("docs/spec");
    for contract in ["cli.md", "dataset-format.md", "diagnosis.md"] {
        assert!(spec.join(contract).is_file(), "docs/spec/{contract} is missing");
    }
    let mut broken = Vec::new();
    for (path, text) in texts() {
        for (idx, _) in text.match_indices("docs/spec/") {
            let name: String = text[idx + "docs/spec/".len()..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '_' || *c == '.')
                .collect();
            let name = name.trim_end_matches('.');
            if !name.is_empty() && !spec.join(name).is_file() {
                broken.push(format!("{}: docs/spec/{name}", path.display()));
            }
        }
    }
    assert!(broken.is_empty(), "contracts named but not in the tree:\n{}", broken.join("\n"));
}

/// The code of the Rust files of module `module` under `dir` (its file, or its folder and its
/// files below), test code left out: files named `tests.rs`, and each item marked
/// `#[cfg(test)]`. Comment lines are dropped.
fn module_code(dir: &Path, module: &str) -> String {
    let mut files = Vec::new();
    let file = dir.join(format!("{module}.rs"));
    if file.is_file() {
        files.push(file);
    }
    let mut stack = vec![dir.join(module)];
    while let Some(folder) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else { continue };
        for entry in entries {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") && path.file_name().is_some_and(|n| n != "tests.rs") {
                files.push(path);
            }
        }
    }
    let mut code = String::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        // The item after each `#[cfg(test)]` is skipped up to where its braces close (or its
        // `;` ends it).
        let (mut skipping, mut depth) = (false, 0i64);
        for line in text.lines().filter(|line| !line.trim_start().starts_with("//")) {
            if line.trim() == "#[cfg(test)]" {
                (skipping, depth) = (true, 0);
                continue;
            }
            if skipping {
                depth += line.matches('{').count() as i64 - line.matches('}').count() as i64;
                let ended = line.trim_end().ends_with('}') || line.trim_end().ends_with(';');
                skipping = !(depth <= 0 && ended);
                continue;
            }
            code.push_str(line);
            code.push('\n');
        }
    }
    code
}

/// A cycle among the modules under `dir` (each module's uses of another by one of `prefixes`
/// and its name), or `None`: the modules then form layers, each using only the ones below it.
fn module_cycle(dir: &Path, prefixes: &[&str]) -> Option<Vec<String>> {
    let mut modules: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("a directory entry").path())
        .filter_map(|path| {
            let stem = path.file_stem()?.to_str()?.to_owned();
            let module = path.is_dir() || path.extension().is_some_and(|e| e == "rs");
            (module && !["lib", "mod", "main", "bin", "tests"].contains(&stem.as_str())).then_some(stem)
        })
        .collect();
    modules.sort();
    modules.dedup();
    let uses = |from: &str| -> Vec<String> {
        let code = module_code(dir, from);
        let names = |name: &str| -> Vec<String> {
            prefixes.iter().flat_map(|p| ["::", ";", "}", ","].map(|end| format!("{p}{name}{end}"))).collect()
        };
        modules
            .iter()
            .filter(|to| *to != from && names(to).iter().any(|n| code.contains(n.as_str())))
            .cloned()
            .collect()
    };
    let edges: std::collections::BTreeMap<String, Vec<String>> = modules.iter().map(|m| (m.clone(), uses(m))).collect();
    // Depth-first search; a module met again on the current path closes a cycle.
    fn visit(
        module: &str,
        edges: &std::collections::BTreeMap<String, Vec<String>>,
        path: &mut Vec<String>,
        done: &mut std::collections::BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(start) = path.iter().position(|m| m == module) {
            let mut cycle = path[start..].to_vec();
            cycle.push(module.to_owned());
            return Some(cycle);
        }
        if done.contains(module) {
            return None;
        }
        path.push(module.to_owned());
        for next in &edges[module] {
            if let Some(cycle) = visit(next, edges, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(module.to_owned());
        None
    }
    let mut done = std::collections::BTreeSet::new();
    modules.iter().find_map(|m| visit(m, &edges, &mut Vec::new(), &mut done))
}

/// Inside each host crate the modules form layers, as the crates do among themselves (which
/// cargo enforces): no module uses one that uses it back (outside tests).
#[test]
fn host_crates_modules_use_each_other_without_a_cycle() {
    let crates = ["sindy", "reports", "model-fit", "evaluation", "diagnosis", "rigs", "host-tools", "xtask"];
    let mut dirs: Vec<(std::path::PathBuf, &[&str])> =
        crates.iter().map(|name| (root().join(name).join("src"), &["crate::"][..])).collect();
    dirs.push((root().join("diagnosis/src/diagnose"), &["super::", "crate::diagnose::"][..]));
    for (dir, prefixes) in dirs {
        if let Some(cycle) = module_cycle(&dir, prefixes) {
            panic!("{}: a module cycle: {}", dir.display(), cycle.join(" -> "));
        }
    }
}
