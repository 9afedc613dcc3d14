#!/usr/bin/env python3
"""collide simulate (serial, rayon on 2 threads, MPI on 2 ranks) against the cell-list
yardstick of `benches/yardstick/`, interleaved, medians of REPS rounds, as a markdown table.

Usage (from the repository's root, an idle machine, a `--features mpi` build):
    cargo build --release --features mpi
    cargo bench --bench kernels --no-run    # prints the bench binary's path
    python3 benches/against_yardstick.py target/release/collide BENCH_BINARY [REPS]

Both time the stepping loop only: collide its `particle_steps_per_s` (every step from
the placed state), the yardstick 50 steps after 10 warm-up steps. The scenes are the
seed's gas with r = 1, v_rms = 1, dt = 0.1, walls, seed 42.

"2 serial at once" is what the machine gives two workers in the same round: two serial
runs started together, their rates summed, over one serial run's. On a VM whose two
cores are sometimes two hardware threads of one physical core it falls well below 2,
and no parallel backend can beat it; the parallel backends' ratios read against it.
"""
import json
import os
import statistics
import subprocess
import sys

collide, bench = sys.argv[1], sys.argv[2]
reps = int(sys.argv[3]) if len(sys.argv) > 3 else 3
env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")
scene = "experiments/scenes/seed-1000.toml"
# 100 steps, as the shipped scaling study (`experiments/large.toml`) runs these scenes.
cases = [(100000, 0.05, 100), (100000, 0.3, 100), (1000000, 0.05, 100), (1000000, 0.3, 100)]
backends = [("serial", []), ("rayon2", ["--backend", "rayon", "--threads", "2"]),
            ("mpi2", ["--backend", "mpi", "--ranks", "2"])]
ours, yardstick, hashes = {}, {}, {}


def simulate(n, packing, steps, args=()):
    """A `collide simulate --json` of the case, started: wait for it with `rate`."""
    return subprocess.Popen([collide, "simulate", scene, "--n", str(n), "--packing",
                             str(packing), "--steps", str(steps), "--seed", "42", "--json",
                             *args], env=env, stdout=subprocess.PIPE, text=True)


def rate(n, packing, run):
    """The rate (M particle-steps/s) of a started `simulate`; its state hash goes to
    `hashes`."""
    out, _ = run.communicate()
    if run.returncode != 0:
        sys.exit(f"collide simulate failed with exit code {run.returncode}")
    result = json.loads(out.strip().splitlines()[-1])
    hashes.setdefault((n, packing), set()).add(result["state_hash"])
    return result["particle_steps_per_s"] / 1e6


for _ in range(reps):
    out = subprocess.run([bench], env=dict(env, COLLIDE_YARDSTICK_ONLY="1"),
                         capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        words = line.split()
        if words and words[0] == "yardstick" and words[1] != "N":
            yardstick.setdefault((int(words[1]), float(words[2])), []).append(float(words[4]))
    for n, packing, steps in cases:
        for name, args in backends:
            ours.setdefault((n, packing, name), []).append(
                rate(n, packing, simulate(n, packing, steps, args)))
        together = [simulate(n, packing, steps) for _ in range(2)]
        ours.setdefault((n, packing, "two"), []).append(
            sum(rate(n, packing, run) for run in together))
print("| N | packing | yardstick | serial | rayon, 2 threads | MPI, 2 ranks | serial / yardstick "
      "| 2 serial at once / serial | rayon / serial | MPI / serial | hashes agree |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for n, packing, _ in cases:
    y = statistics.median(yardstick[(n, packing)])
    m = {name: statistics.median(ours[(n, packing, name)])
         for name in [name for name, _ in backends] + ["two"]}
    print(f"| {n:.0e} | {packing} | {y:.1f} M/s | {m['serial']:.1f} M/s | {m['rayon2']:.1f} M/s "
          f"| {m['mpi2']:.1f} M/s | {m['serial'] / y:.2f}× | {m['two'] / m['serial']:.2f}× "
          f"| {m['rayon2'] / m['serial']:.2f}× "
          f"| {m['mpi2'] / m['serial']:.2f}× | {len(hashes[(n, packing)]) == 1} |")
