#!/usr/bin/env bash
# The test command: formatting, lints, the whole test suite, the no_std build of the core for the
# flight controller's Cortex-M4F and the link-time proof that its step cannot panic. Safe to run
# again: every install step is idempotent.
#
#   ./ci.sh          all jobs
#   ./ci.sh JOB ...  some of: setup fmt clippy test doc nostd python foreign
set -euo pipefail
cd "$(dirname "$0")"
# The virtual environment of the `python` job.
VENV="$(pwd)/${CARGO_TARGET_DIR:-target}/python-venv"
# The host-tools binary the `python` and `foreign` jobs run: the one the `test` job built for the
# command line's end-to-end test (the test profile: optimised, with line tables; a diagnosis
# runs about 8 % slower than in the release build), so that CI does not build the workspace
# a second time. `cargo test --no-run` builds it when the test job did not run first.
export ROLLEST_HOST_TOOLS="$(pwd)/${CARGO_TARGET_DIR:-target}/debug/host-tools"
test_binary() { cargo test --workspace --no-run --quiet 2>/dev/null || cargo test --workspace --no-run; }

setup() {
    # The toolchain itself comes from rust-toolchain.toml; add what a fresh machine lacks.
    rustup component add rustfmt clippy >/dev/null
    rustup target add thumbv7em-none-eabihf >/dev/null
    # QEMU runs the firmware (netduinoplus2 = STM32F405) in the tests; arm-none-eabi-gcc and
    # newlib build the C example that flies the estimator's C interface there.
    local packages=()
    command -v qemu-system-arm >/dev/null || packages+=(qemu-system-arm)
    command -v arm-none-eabi-gcc >/dev/null || packages+=(gcc-arm-none-eabi)
    [ -n "$(arm-none-eabi-gcc -print-file-name=rdimon.specs 2>/dev/null | grep /)" ] \
        || packages+=(libnewlib-arm-none-eabi)
    if [ ${#packages[@]} -gt 0 ]; then
        local sudo=""
        [ "$(id -u)" = 0 ] || sudo=sudo
        $sudo apt-get update -qq
        $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${packages[@]}" >/dev/null
    fi
    # numpy and scipy run the second, independent tunnel of the `foreign` job (tools/foreign-tunnel).
    python3 -c "import numpy, scipy" 2>/dev/null \
        || python3 -m pip install --quiet --disable-pip-version-check -r tools/foreign-tunnel/requirements.txt
}

fmt() { cargo fmt --all -- --check; }

clippy() { cargo clippy --workspace --all-targets -- -D warnings; }

# Both tiers: plain `cargo test` runs the fast one; the slow tier (QEMU, the soak, full
# campaigns and diagnoses) is `#[ignore = "slow tier ..."]` and runs here. Not through
# cargo-nextest: it runs every test in a process of its own, so the fixtures a test binary makes
# once (the default campaign, the fitted clean model) are made once per test, and the suite
# took 339 s there against 280 s here, on one machine.
test() { cargo test --workspace -- --include-ignored; }

doc() { RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps; }

nostd() {
    cargo build -p estimator-core --target thumbv7em-none-eabihf --release
    cargo build -p estimator-core --target thumbv7em-none-eabihf --release --features defmt
    # The core's measurement variants (`cargo xtask weigh`): they must keep building.
    cargo build -p estimator-core --target thumbv7em-none-eabihf --release --features micromath,nalgebra
    # The firmware as it ships (the `firmware` profile), which shares its crates with the proof below.
    cargo build -p firmware-sim --bin firmware --no-default-features --features target --target thumbv7em-none-eabihf --profile firmware
    # Link-time proof that Estimator::step has no panic path (firmware-sim/src/bin/panic_check.rs):
    # the link fails if one survives whole-program optimisation.
    cargo build -p firmware-sim --bin panic_check --no-default-features --features target --target thumbv7em-none-eabihf --profile firmware
}

# The Python package (`rollest`): installed as the README says, its pytest suite against the
# command line, its type stubs against the built module (mypy's stubtest), the wrappers typed.
python() {
    test_binary
    # A clean virtual environment each time, as a user's: the wheel and the suite's requirements
    # (pytest, pandas, mypy, PySINDy, matplotlib, h5py, nbmake, Dask's distributed).
    rm -rf "$VENV"
    python3 -m venv "$VENV"
    local pip=("$VENV/bin/pip" --quiet --disable-pip-version-check)
    # One abi3 wheel, built by maturin through pip's PEP 517 build (what `pip install ./python`
    # runs), in the dev profile, which the test profile is: it reuses the test job's compiled
    # crates where their features agree, instead of a third build of the workspace (the README's
    # install builds the release wheel; the code is the same).
    local wheels="${CARGO_TARGET_DIR:-target}/wheels"
    rm -rf "$wheels"
    MATURIN_PEP517_ARGS="--profile dev" "${pip[@]}" wheel --no-deps ./python -w "$wheels"
    "${pip[@]}" install "$wheels"/rollest-*-abi3-*.whl -r python/requirements-test.txt
    "$VENV/bin/pytest" -q python/tests
    # The example notebook, executed cell by cell (nbmake): simulate, fit, evaluate, plot,
    # diagnose; its three figures are written as SVG files, which must not be empty.
    local figures="${CARGO_TARGET_DIR:-target}/notebook-figures"
    rm -rf "$figures"
    ROLLEST_FIGURES="$(pwd)/$figures" "$VENV/bin/pytest" -q --nbmake python/examples/notebook.ipynb
    for figure in measured_vs_estimated heldout_error_per_alpha gap_location; do
        [ -s "$figures/$figure.svg" ] || { echo "the notebook wrote no $figures/$figure.svg" >&2; exit 1; }
    done
    (cd "$VENV" && bin/python -m mypy.stubtest rollest._rollest)
    "$VENV/bin/python" -m mypy --strict --no-incremental python/rollest
}

# Datasets from a second tunnel written apart from firmware-sim's (other equations, excitation,
# noise and file conventions): a slice of a blind campaign, its seed taken from the commit under
# test and every case on its own seed (campaign_check.sh), so no fixed slice can be tuned to.
# `tools/foreign-tunnel/check.sh` (five effects on one fixed seed) stays a tool, not a gate.
foreign() {
    test_binary
    # The Python package on a recording the other program wrote (the `python` job installed it).
    local recording="${CARGO_TARGET_DIR:-target}/foreign-tunnel/bias_drift"
    rm -rf "$recording"
    python3 tools/foreign-tunnel/foreign_tunnel.py --seed 1 --duration-s 30 --alphas 4,18 \
        --effect bias_drift --out "$recording" 2>/dev/null
    ROLLEST_FOREIGN_DATA="$recording" "$VENV/bin/pytest" -q python/tests -k another_program
    tools/foreign-tunnel/campaign_check.sh "${CARGO_TARGET_DIR:-target}/foreign-campaign"
}

jobs=("$@")
[ ${#jobs[@]} -gt 0 ] || jobs=(setup fmt clippy test doc nostd python foreign)
for job in "${jobs[@]}"; do
    echo "== ci: $job"
    started=$SECONDS
    "$job"
    echo "== ci: $job took $((SECONDS - started)) s"
done
echo "== ci: all jobs passed in $SECONDS s"
