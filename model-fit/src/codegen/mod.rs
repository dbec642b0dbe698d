//! Code generation: a coefficient set as Rust const tables in estimator-core
//! (the module folder `estimator-core/src/coeffs/generated/`), committed; `--check` compares instead of
//! writing, so a stale file fails CI (the rust-analyzer `cargo codegen` pattern).
//!
//! The tables are written from the types' serde form ([`literal`]): every f32 as the shortest
//! decimal that reads back to the same bits, so the generated const is bit-identical to the
//! blob it came from. The source is parsed by syn and printed by prettyplease, in process; the
//! module is `#[rustfmt::skip]`, so `cargo fmt` leaves the printer's layout as it is.

pub mod literal;

use std::path::{Path, PathBuf};

use estimator_core::CoefficientSet;
use estimator_core::coeffs::MAX_VARS;

use literal::{LiteralError, f32_literal};

/// Why code generation failed.
#[derive(Debug, thiserror::Error)]
pub enum CodegenError {
    /// The coefficient set does not pass the blob's validation (non-finite values, bad sizes).
    #[error("the coefficient set is not valid: {0}")]
    Invalid(estimator_core::blob::InvalidSet),
    /// The set could not be written as a blob (whose hash the header states).
    #[error("the coefficient set cannot be written as a blob: {0}")]
    Blob(crate::model::ToBlobError),
    /// A table has no Rust literal (a value a const cannot hold).
    #[error("the coefficient set has no Rust literal: {0}")]
    Literal(#[from] LiteralError),
    /// The generated source does not parse as Rust (a fault of this generator).
    #[error("the generated source does not parse: {0}")]
    Parse(String),
    /// Reading or writing the generated file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The generated module's folder could not be replaced (the old one is left as it was).
    #[error(transparent)]
    Folder(#[from] firmware_sim::atomic::FolderError),
    /// `--check`: the committed file differs from what the model generates.
    #[error(
        "{path} is stale: it differs from the tables generated from {model}; run `host-tools codegen --model {model}` and commit the result"
    )]
    Stale {
        /// The generated file.
        path: PathBuf,
        /// The model it was compared against.
        model: String,
    },
}

/// Provenance of the committed default tables.
pub const DEFAULT_PROVENANCE: &str =
    "the fit on the default synthetic campaign (host-tools simulate, seed 1; host-tools fit; models/default)";

/// The workspace `host-tools` runs in: the nearest folder at or above the current directory
/// whose `Cargo.toml` has a `[workspace]` table, as cargo finds it. Found at run time, so a
/// binary built elsewhere writes into the tree it is run from.
#[must_use]
pub fn workspace_root() -> Option<PathBuf> {
    let here = std::env::current_dir().ok()?;
    here.ancestors()
        .find(|dir| {
            std::fs::read_to_string(dir.join("Cargo.toml"))
                .is_ok_and(|text| text.lines().any(|line| line.trim() == "[workspace]"))
        })
        .map(Path::to_path_buf)
}

/// `relative` in the workspace (else relative to the current directory).
fn in_workspace(relative: &str) -> PathBuf {
    let path = workspace_root().map_or_else(|| PathBuf::from(relative), |root| root.join(relative));
    std::fs::canonicalize(&path).unwrap_or(path)
}

/// The committed default model folder of the workspace.
#[must_use]
pub fn default_model() -> PathBuf {
    in_workspace("models/default")
}

/// The generated module's folder in the workspace, `codegen`'s `--out` when none is given.
#[must_use]
pub fn default_target() -> PathBuf {
    in_workspace("estimator-core/src/coeffs/generated")
}

/// The generated module: its files by name, in the order they are written (`mod.rs` first).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Generated {
    /// `(file name, formatted source)`.
    pub files: Vec<(String, String)>,
}

/// The file that makes a folder the generated module (and lets `write` replace it).
const MODULE_FILE: &str = "mod.rs";

/// The coefficient set's large fields, each a const in a file of its own so that no generated
/// file is a wall of a thousand lines: `(module, the const, its type)`; a module's file
/// (`egk.rs`) also holds the straight-line code of the field's sparse models.
const PARTS: [(&str, &str, &str); 4] = [
    ("egk", "EGK", "[EgkParams; N_ALPHA]"),
    ("pressure", "PRESSURE", "PressureModel"),
    ("plant", "PLANT", "[PlantParams; 2]"),
    ("coupling", "COUPLING", "SparseModel"),
];

/// The types a generated file may name, with where they come from; a file imports those its
/// source uses.
const NAMES: [(&str, &str); 17] = [
    ("ActuatorResponse", "crate::coeffs"),
    ("CoefficientSet", "crate::coeffs"),
    ("ControllerParams", "crate::coeffs"),
    ("EgkParams", "crate::coeffs"),
    ("Envelope", "crate::coeffs"),
    ("FusionParams", "crate::coeffs"),
    ("MAX_VARS", "crate::coeffs"),
    ("N_ALPHA", "crate::coeffs"),
    ("PlantParams", "crate::coeffs"),
    ("PressureModel", "crate::coeffs"),
    ("RateFilter", "crate::coeffs"),
    ("coupling_var", "crate::coeffs"),
    ("plant_var", "crate::coeffs"),
    ("Factor", "crate::sparse"),
    ("Monomial", "crate::sparse"),
    ("SparseModel", "crate::sparse"),
    ("Term", "crate::sparse"),
];

/// The `use` lines for the names `code` uses (a name counts when it stands as a whole word).
fn imports(code: &str) -> String {
    let used = |name: &str| {
        code.match_indices(name).any(|(at, _)| {
            let before = code[..at].chars().next_back();
            let after = code[at + name.len()..].chars().next();
            let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
            !word(before) && !word(after)
        })
    };
    let mut lines = String::new();
    for module in ["crate::coeffs", "crate::sparse"] {
        let names: Vec<&str> =
            NAMES.iter().filter(|(name, from)| *from == module && used(name)).map(|(name, _)| *name).collect();
        if !names.is_empty() {
            lines.push_str(&format!("use {module}::{{{}}};\n", names.join(", ")));
        }
    }
    lines
}

/// Parses `source` and prints it as prettyplease lays it out.
fn formatted(source: &str) -> Result<String, CodegenError> {
    let file = syn::parse_file(source).map_err(|error| CodegenError::Parse(error.to_string()))?;
    Ok(prettyplease::unparse(&file))
}

/// The generated module for `set`, formatted; `provenance` says where the tables come from.
///
/// `mod.rs` holds the provenance, the small fields and `DEFAULT`; the eGK schedule, the
/// pressure model, the plants and the coupling operator are consts of their own files, next to
/// the straight-line code of their sparse models.
pub fn render(set: &CoefficientSet, provenance: &str) -> Result<Generated, CodegenError> {
    estimator_core::blob::validate(set).map_err(CodegenError::Invalid)?;
    let models = [
        ("plant", "plant_port", "plant[0].model", &set.plant[0].model, &PLANT_VARS),
        ("plant", "plant_starboard", "plant[1].model", &set.plant[1].model, &PLANT_VARS),
        ("coupling", "coupling", "coupling", &set.coupling, &COUPLING_VARS),
    ];
    // Validated above, so only the encoding itself can fail here.
    let blob = crate::model::encode(set).map_err(CodegenError::Blob)?;
    let terms: Vec<String> =
        models.iter().map(|(_, _, what, model, _)| format!("{what} {} terms", model.active_terms().len())).collect();
    let literals = [
        literal::to_rust(&set.egk)?,
        literal::to_rust(&set.pressure)?,
        literal::to_rust(&set.plant)?,
        literal::to_rust(&set.coupling)?,
    ];
    let mut parts = Vec::new();
    for ((module, name, ty), value) in PARTS.iter().zip(&literals) {
        let functions: String = models
            .iter()
            .filter(|(of, ..)| of == module)
            .map(|&(_, function, what, model, vars)| compiled_model(function, what, model, vars))
            .collect();
        let code = format!("/// `DEFAULT.{module}`.\npub(super) const {name}: {ty} = {value};\n{functions}");
        let source = format!(
            "//! `DEFAULT.{module}`, generated by `host-tools codegen` with the rest of `DEFAULT` (`mod.rs`); do \
             not edit by hand.\n\n{}\n{code}",
            imports(&code)
        );
        parts.push((format!("{module}.rs"), formatted(&source)?));
    }
    // The small fields stay in `mod.rs`; the large ones name their files' consts.
    let mut default = literal::to_rust(set)?;
    for ((module, name, _), value) in PARTS.iter().zip(&literals) {
        let field = format!("{module}: {value}");
        if !default.contains(&field) {
            return Err(CodegenError::Parse(format!("the field `{module}` is not in the set's literal")));
        }
        default = default.replacen(&field, &format!("{module}: {module}::{name}"), 1);
    }
    let functions: Vec<String> = models.iter().map(|(module, function, ..)| format!("{module}::{function}")).collect();
    let code = format!(
        "/// The default coefficient set compiled into the estimator: {provenance}\n\
         pub const DEFAULT: CoefficientSet = {default};\n"
    );
    let root = format!(
        "//! Generated by `host-tools codegen`, do not edit by hand.\n//!\n//! Source: {provenance}.\n\
         //! Blob: {} bytes, SHA-256 {}, schema version {}.\n//! Sparse models: {}.\n\n\
         {}\n\n{}\npub(super) use {{{}}};\n\n{code}",
        blob.len(),
        crate::digest::sha256_hex(&blob),
        set.schema_version,
        terms.join(", "),
        PARTS.iter().map(|(module, ..)| format!("mod {module};")).collect::<Vec<_>>().join("\n"),
        imports(&code),
        functions.join(", "),
    );
    let mut files = vec![(MODULE_FILE.to_owned(), formatted(&root)?)];
    files.extend(parts);
    Ok(Generated { files })
}

/// A sparse model of [`estimator_core::coeffs::DEFAULT`] as a function of straight-line code
/// (`estimator_core::coeffs::CompiledDefault`): the operations of
/// [`estimator_core::sparse::SparseModel::eval`] in the same order, with the coefficients and
/// gate thresholds as literals (the shortest decimal that reads back to the same f32,
/// [`f32_literal`]) and the factors as fixed indices. The padding factor multiplies by 1, which is exact,
/// so it is left out; a term gated on a variable the core does not have is never active, so
/// it is left out too. The result is bit-identical to the interpreted model.
fn compiled_model(
    name: &str,
    what: &str,
    model: &estimator_core::sparse::SparseModel,
    vars: &[&str; MAX_VARS],
) -> String {
    let mut body = String::new();
    for term in model.active_terms() {
        if term.monomial.gate_mask >> MAX_VARS != 0 {
            continue;
        }
        let mut product = format!("{}f32", f32_literal(term.coeff));
        for &factor in &term.monomial.factors {
            if factor.index() < MAX_VARS {
                product.push_str(&format!(" * x[{}]", vars[factor.index()]));
            }
        }
        let gates: Vec<String> = (0..MAX_VARS)
            .filter(|&var| term.monomial.gate_mask & (1 << var) != 0)
            .map(|var| format!("x[{}].abs() > {}f32", vars[var], f32_literal(model.gate_threshold[var])))
            .collect();
        if gates.is_empty() {
            body.push_str(&format!("    sum += {product};\n"));
        } else {
            body.push_str(&format!("    if {} {{\n        sum += {product};\n    }}\n", gates.join(" && ")));
        }
    }
    let (binding, param) = if body.is_empty() { ("let sum", "_x") } else { ("let mut sum", "x") };
    format!(
        "\n/// `DEFAULT.{what}` as straight-line code ({} terms), bit-identical to `SparseModel::eval` of the\n/// tables.\n\
         #[inline]\n#[must_use]\n\
         pub(in crate::coeffs) fn {name}({param}: &[f32; MAX_VARS]) -> f32 {{\n    {binding} = -0.0f32;\n{body}    sum\n}}\n",
        model.active_terms().len()
    )
}

/// The plant's variables by index, as the generated code names them
/// (`estimator_core::coeffs::plant_var`; indices 5 and 6 are not plant variables).
const PLANT_VARS: [&str; MAX_VARS] =
    ["plant_var::CL_AFC", "plant_var::CMU", "plant_var::DCMU", "plant_var::ALPHA", "plant_var::CL_SLOW", "5", "6"];

/// The coupling operator's variables by index (`estimator_core::coeffs::coupling_var`).
const COUPLING_VARS: [&str; MAX_VARS] = [
    "coupling_var::CL_ROLL",
    "coupling_var::CL_AFC",
    "coupling_var::ALPHA",
    "coupling_var::CMU",
    "coupling_var::DCMU",
    "coupling_var::PHI",
    "coupling_var::PHI_DOT",
];

/// Writes the generated module's folder, whole or not at all: a folder that already holds a
/// `mod.rs` is replaced once the new one is complete, and a stale file of an earlier layout
/// cannot survive.
pub fn write(target: &Path, generated: &Generated) -> Result<(), CodegenError> {
    firmware_sim::atomic::write_folder::<CodegenError>(target, MODULE_FILE, |tmp| {
        for (name, source) in &generated.files {
            let path = tmp.join(name);
            std::fs::write(&path, source).map_err(|source| CodegenError::Io { path, source })?;
        }
        Ok(())
    })
}

/// Compares the committed folder with `generated`: the same files, each with the same text, and
/// no other source file.
pub fn check(target: &Path, generated: &Generated, model: &str) -> Result<(), CodegenError> {
    let stale = || CodegenError::Stale { path: target.to_path_buf(), model: model.to_owned() };
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CodegenError::Io { path, source }
    };
    let mut committed: Vec<String> = std::fs::read_dir(target)
        .map_err(io(target))?
        .filter_map(Result::ok)
        .map(|entry| entry.file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".rs"))
        .collect();
    committed.sort();
    let mut expected: Vec<String> = generated.files.iter().map(|(name, _)| name.clone()).collect();
    expected.sort();
    if committed != expected {
        return Err(stale());
    }
    for (name, source) in &generated.files {
        let path = target.join(name);
        if std::fs::read_to_string(&path).map_err(io(&path))? != *source {
            return Err(stale());
        }
    }
    Ok(())
}
