#!/usr/bin/env bash
# The wheel as a user gets it: build it from this checkout, install it into a fresh venv in a temporary directory
# outside the checkout, and run from there what the README's tour starts with: --version, the scenario and method
# lists, a shipped scenario's whole episode, a scenario file of one's own with a log, and the Python API.
# `make test` runs it after the test suite.
#
# Two modes:
# - full (in CI, where CI=true, or with WHEEL_CHECK_FULL=1): the wheel and its dependencies are installed from the
#   package index with the versions of constraints.txt, as a user would (about 1 GB; 1-2 minutes here, most of it
#   writing and deleting files). This also catches a module that imports a package the wheel does not declare.
# - quick (otherwise): the wheel is installed without dependencies and the fresh venv borrows them from .venv (one
#   .pth line: the checkout's editable install is not activated by it). This checks what differs between the
#   wheel and the checkout (the package's files and data, entry points, the console script) in seconds.
# Either way the script fails unless bigcbf and twin are imported from the fresh venv.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
BASE_PY=$("$PY" -c 'import sys; print(getattr(sys, "_base_executable", sys.executable))')
tmp=$(mktemp -d "${TMPDIR:-/tmp}/bigcbf-wheel-check.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
t0=$SECONDS
rm -rf build                                  # setuptools' in-tree build cache could carry deleted modules along
"$PY" -m pip wheel -q --no-deps -w "$tmp/dist" . 2>&1 | grep -v "is ignored" || true
wheel=$(ls "$tmp"/dist/bigcbf-*.whl)
"$BASE_PY" -m venv "$tmp/venv"
if [ "${CI:-}" = "true" ] || [ "${WHEEL_CHECK_FULL:-0}" = "1" ]; then
    mode="full: dependencies from the index"
    "$tmp/venv/bin/python" -m pip install -q -c constraints.txt "$wheel" 2>&1 | grep -v "is ignored" || true
else
    mode="quick: dependencies borrowed from .venv"
    "$tmp/venv/bin/python" -m pip install -q --no-deps "$wheel" 2>&1 | grep -v "is ignored" || true
    site_new=$("$tmp/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    # the dependencies' folder, then the start-up lines of its own .pth files (cmeel's puts proxsuite on the path),
    # except the editable install's, which would map bigcbf to the checkout
    "$PY" -c '
import pathlib, sysconfig
site = pathlib.Path(sysconfig.get_paths()["purelib"])
print(site)
for pth in sorted(site.glob("*.pth")):
    if not pth.name.startswith("__editable__"):
        print(*[line for line in pth.read_text().splitlines() if line.startswith("import")], sep="\n")
' > "$site_new/zz_borrowed_dependencies.pth"
fi
cp constraints.txt "$tmp/"
README="$PWD/README.md"
cd "$tmp"                                     # nothing of the checkout is on the path from here on
export MUJOCO_GL=${MUJOCO_GL:-egl}
B="$tmp/venv/bin/bigcbf"
echo "wheel check ($mode): $(basename "$wheel") installed into a fresh venv in $tmp ($((SECONDS - t0)) s)"
"$tmp/venv/bin/python" -c "
import bigcbf, twin, sys
for m in (bigcbf, twin):
    assert m.__file__.startswith('$tmp/venv/'), f'{m.__name__} imported from {m.__file__}, not from the fresh venv'
print('bigcbf imported from', bigcbf.__file__)"
"$B" --version
"$B" scenarios | cut -c1-100 | tee scenarios.txt
n=$(wc -l < scenarios.txt)
[ "$n" -eq 9 ] || { echo "wheel check: expected 9 scenarios, got $n" >&2; exit 1; }
"$B" methods
"$B" run required_sidestepping --method big-cbf --seed 0 --json > run.json
"$tmp/venv/bin/python" -c "import json; r = json.load(open('run.json')); print('required_sidestepping big-cbf seed 0:', {k: r[k] for k in ('success', 'collision', 'time_s', 'min_clearance_m')}); assert r['success'] and not r['collision']"
sed 's/^time_limit_s = .*/time_limit_s = 3.0/' "$("$tmp/venv/bin/python" -c 'import bigcbf; print(bigcbf.SCENARIOS)')/corridor_meeting.toml" > my_scene.toml
"$B" run my_scene.toml --method dwa --seed 3 --log my_scene.mcap | grep -E "^(scenario|sim_time_s|wrote)"
"$tmp/venv/bin/python" -c "import bigcbf; r = bigcbf.run_episode('single_person_crossing', 'cbf-only', seed=1, time_limit_s=2.0); print('API:', type(r).__name__, r.sim_time_s, 's')"
if [ "$mode" != "${mode#full}" ] || [ "${WHEEL_CHECK_TOUR:-0}" = "1" ]; then
    # the README's tour, line by line, with this venv's bigcbf and python first on the PATH
    mkdir tour && cd tour
    awk '/^A tour/ {on = 1; next} on && /^    / {print substr($0, 5); seen = 1; next} on && seen {exit}' \
        "$README" > tour.sh
    echo "the README's tour ($(wc -l < tour.sh) commands):"
    while IFS= read -r line; do
        echo "\$ $line"
        PATH="$tmp/venv/bin:$PATH" bash -c "$line" > out.txt 2>&1 || { cat out.txt; echo "wheel check: failed: $line" >&2; exit 1; }
        tail -n 3 out.txt | cut -c1-160
    done < tour.sh
    cd ..
fi
echo "wheel check passed ($((SECONDS - t0)) s, then deleting the venv)"
