"""Reads a study's Parquet records with pyarrow, as a Python user would, and checks them.

Usage: python3 .ci/read_results.py RESULTS_DIR
"""
import glob
import pathlib
import re
import sys

import pyarrow.parquet as pq

REQUIRED = [
    "schema_version", "study", "scene", "n", "packing", "dt", "steps", "backend",
    "threads", "ranks", "workers", "repetition", "status", "wall_s", "fps",
    "particle_steps_per_s", "integration_s", "broad_phase_s", "collision_s",
    "communication_s", "kinetic_energy_initial", "kinetic_energy_final",
    "momentum_initial_x", "momentum_final_y", "pair_collisions", "max_overlap",
    "state_hash", "oversubscribed", "git_commit", "cpu_model", "hostname",
]

files = sorted(glob.glob(f"{sys.argv[1]}/*.parquet"))
assert files, f"no Parquet files in {sys.argv[1]}"
table = pq.read_table(files[-1])
missing = [c for c in REQUIRED if c not in table.column_names]
assert not missing, f"missing columns: {missing}"
rows = table.to_pylist()
assert rows and all(r["status"] == "ok" for r in rows), "a run failed"
# The version the collide that wrote them declares: the newest `@VERSION` mark of the
# column list in src/study/records.rs, as SCHEMA_VERSION is derived there.
records_rs = pathlib.Path(__file__).resolve().parent.parent / "src" / "study" / "records.rs"
version = max(int(mark) for mark in re.findall(r"\s@(\d+)\b", records_rs.read_text()))
assert all(r["schema_version"] == version for r in rows), f"schema version is not {version}"
hashes = {}
for r in rows:
    hashes.setdefault(r["n"], set()).add(r["state_hash"])
assert all(len(h) == 1 for h in hashes.values()), f"backends disagree: {hashes}"
backends = sorted({(r["backend"], r["workers"]) for r in rows})
print(f"pyarrow read {len(rows)} rows, {len(table.column_names)} columns from {files[-1]}")
print(f"backends {backends}; state_hash agrees per n: {sorted(hashes)}")
