"""Guard for refactors that must keep results: SHA-1 of every numeric dataset of every smoke
case's final states, recorded before a large change and compared after it.

    python tests/guards/smoke_hashes.py record    # writes tests/guards/smoke_hashes.json
    python tests/guards/smoke_hashes.py compare   # exit 1 and a list of the datasets that differ

(``make hashes`` and ``make guard``.) Bit-identity holds on one kind of machine only (another
CPU rounds differently, and a packing amplifies it into another realisation: README,
"Running"), so the file keeps the machine it was recorded on (:func:`demcli.machine.machine`)
and ``compare`` refuses to compare across machines: record at the commit before the change,
on the machine that makes it. Not part of ``make test``: it runs every smoke case in full
(minutes), and a file recorded elsewhere would not apply.
"""

import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = Path(__file__).with_name("smoke_hashes.json")
SMOKE = sorted((ROOT / "cases" / "smoke").glob("*.yaml"))


def dataset_hashes(path):
    """{dataset: SHA-1 of its bytes} of the numeric datasets of one state file."""
    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.dtype.kind in "biuf":
            out[name] = hashlib.sha1(np.ascontiguousarray(obj[()]).tobytes()).hexdigest()

    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return out


def smoke_hashes(log=print, cases=SMOKE):
    """{case: {state file: {dataset: sha1}}} of the smoke cases (default: all) run afresh, one thread."""
    from demcli import run_case

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            t0 = time.perf_counter()
            res = run_case(case, out=Path(tmp) / case.stem, quiet=True, threads=1)
            out[case.name] = {r.path.name: dataset_hashes(r.path) for r in res}
            log(f"{case.name}: {len(res)} states, {time.perf_counter() - t0:.1f} s")
    return out


def differences(old, new):
    """Lines naming each dataset that differs, is new or is gone, case by case."""
    lines = []
    for case in sorted(set(old) | set(new)):
        a, b = old.get(case, {}), new.get(case, {})
        for state in sorted(set(a) | set(b)):
            da, db = a.get(state, {}), b.get(state, {})
            for ds in sorted(set(da) | set(db)):
                if ds not in da:
                    lines.append(f"{case} {state} {ds}: new")
                elif ds not in db:
                    lines.append(f"{case} {state} {ds}: gone")
                elif da[ds] != db[ds]:
                    lines.append(f"{case} {state} {ds}: differs")
    return lines


def main(argv=None):
    import subprocess

    from demcli.machine import machine

    mode = (argv or sys.argv[1:] or ["compare"])[0]
    if mode == "record":
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip()
        FIXTURE.write_text(json.dumps({"machine": machine(), "commit": commit, "cases": smoke_hashes()},
                                      indent=1, sort_keys=True) + "\n")
        print(f"recorded {FIXTURE} at {commit}")
        return 0
    rec = json.loads(FIXTURE.read_text())
    if rec["machine"] != machine():
        print(f"{FIXTURE.name} was recorded on another machine:\n  {rec['machine']}\nthis one:\n  {machine()}\n"
              "record it here at the commit before the change (make hashes) and compare again")
        return 2
    unrecorded = [c.name for c in SMOKE if c.name not in rec["cases"]]
    if unrecorded:  # added after the recording: nothing to compare them with
        print(f"not recorded at {rec['commit']}, not compared: {', '.join(unrecorded)}")
    diff = differences(rec["cases"], smoke_hashes(cases=[c for c in SMOKE if c.name in rec["cases"]]))
    for line in diff:
        print(line)
    print(f"{len(diff)} dataset(s) differ from the hashes recorded at {rec['commit']}" if diff else
          f"every smoke case reproduces the hashes recorded at {rec['commit']}, bit for bit")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
