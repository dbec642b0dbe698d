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
