# Shared by check.sh and other_seeds.sh (sourced): where things are, and the two steps both
# take. Sets `here`, `tools` (the host-tools binary: $ROLLEST_HOST_TOOLS, else the release
# build) and `work` (the first argument, or a new temporary folder).
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
tools="${ROLLEST_HOST_TOOLS:-${CARGO_TARGET_DIR:-$root/target}/release/host-tools}"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"

# A recording of the second tunnel: foreign_tunnel.py with the given arguments.
generate() { python3 "$here/foreign_tunnel.py" "$@" 2>/dev/null; }

# `diagnose --real DATASET --model MODEL --report DIR`, then prints the verdict and the named
# effects ("name (shrink x.xx)", comma-separated; "-" for none) of its diagnosis.json.
diagnosis() {
    rm -rf "$3"
    "$tools" diagnose --real "$1" --model "$2" --report "$3" >/dev/null 2>&1
    python3 - "$3/diagnosis.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
named = ", ".join(f"{e['name']} (shrink {e['shrink']:.2f})" for e in d["effects"]) or "-"
print(d["verdict"], named)
PY
}
