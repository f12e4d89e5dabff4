"""A year of hourly suns over the city block: direct-sun counts on ≥ 1 M sensors, four ways.

    python bench/sun_hours.py [--spacing 0.2] [--every 40] [--rounds 2] [--quick]

The study of issue 17: ``scenes/city_block.toml`` (36 buildings, 798 triangles), its sensor grids at
``--spacing`` (0.2 m: 1,002,001 ground + ~260 k roof sensors), the sun of 2026 at its site (Paris) every
hour, above the horizon (~4,450 positions). Timed, on every ``--every``-th sun of the year (a measured
fraction; the year is extrapolated from it, per sun), in interleaved rounds (median of ``--rounds``):

- ``exact`` one process: ``sc.shadow_counts(scene, suns, sensors, normals)`` (PoCL, 2 threads);
- ``exact`` on a 2-worker ``LocalCluster`` (processes, 1 Dask thread and 1 PoCL thread each), the
  same call with ``client=``;
- Embree: bench/peers.py's ``EmbreePeer`` (embreex, 2 worker processes), one occlusion query per sensor
  per sun, masks summed (the BVH of 798 triangles rebuilt per sun: ~1 ms);
- Mitsuba 3 (``MitsubaPeer``, LLVM backend) when it imports, the same loop.

Each tool's counts over the timed suns are compared with exact's (sensors whose count differs), and
on a sample of steps each per-step mask with Embree's (receivers differing per step).

Then what a cluster costs (docs/distributed.md): the round trip of a no-op task, submitted 200 at a
time; a run of ``shadow_counts`` over 40 single-light batches on 8 sensors (its per-batch time is the
overhead of a batch); what is scattered once and what each batch sends and returns, in bytes; the
scatter's time. Writes bench/results/sun_hours.json and .md.
"""

from __future__ import annotations

import argparse
import os
import pickle
import time
from pathlib import Path

import numpy as np

import report
import run
from peers import EmbreePeer, MitsubaPeer
import shadowcl as sc
from shadowcl.counts import BATCH
from shadowcl.distributed import local_cluster
from shadowcl.methods import default_eps
from shadowcl.sensors import scene_sensors
from timing import clock

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "city_block.toml"
RESULTS = Path(__file__).resolve().parent / "results"
AGREEMENT_STEPS = 8


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=0.2, help="sensor grid step in metres (0.2: > 1.2 M sensors)")
    parser.add_argument("--every", type=int, default=40, help="time every k-th sun of the year")
    parser.add_argument("--rounds", type=int, default=2, help="interleaved timed rounds (median)")
    parser.add_argument("--quick", action="store_true", help="spacing 2 m, every 400th sun, one round")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.quick:
        args.spacing, args.every, args.rounds = 2.0, 400, 1
    from dask.distributed import Client

    scene = sc.Scene.load(SCENE)
    site = scene.sun
    grids = scene_sensors(scene, args.spacing)
    points = np.concatenate([g.points for g in grids])
    normals = np.concatenate([g.normals for g in grids])
    year = sc.sun_lights(site["latitude"], site["longitude"], start=site["start"], end=site["end"],
                         step=site["step"], north=site["north"])
    suns = year[::args.every]
    n, eps = len(points), default_eps(scene.mesh.bounds)
    print(f"{n} sensors ({', '.join(f'{g.name} {len(g.points)}' for g in grids)}), {len(year)} suns in the year, "
          f"timing {len(suns)} (every {args.every}th)")
    device = sc.get_device()
    embree, mitsuba = EmbreePeer(workers=2), (MitsubaPeer() if run.available("mitsuba") is None else None)
    load_start = os.getloadavg()

    def peer_counts(peer):
        counts = np.zeros(n)
        for sun in suns:
            peer.prepare(scene.mesh, sun, None, eps)
            counts += peer.classify(points, normals)
        return counts

    with local_cluster(2, threads=1) as cluster, Client(cluster) as client:
        tools = {
            "exact, 1 process (2 threads)": lambda: sc.shadow_counts(scene, suns, points, normals, device=device),
            "exact, LocalCluster 2 x 1": lambda: sc.shadow_counts(scene, suns, points, normals, client=client),
            "embreex (2 processes)": lambda: peer_counts(embree),
        }
        if mitsuba is not None:
            tools["mitsuba (llvm)"] = lambda: peer_counts(mitsuba)
        # warm-up: kernels built in every process, the cluster's workers and Embree's processes started
        sc.shadow_counts(scene, suns[:2], points[:1000], normals[:1000], device=device)
        sc.shadow_counts(scene, suns[:2 * BATCH], points[:1000], normals[:1000], client=client)
        seconds = {name: [] for name in tools}
        counts = {}
        for _ in range(args.rounds):
            for name, call in tools.items():
                elapsed, counts[name] = clock(call)
                seconds[name].append(elapsed)
                print(f"{name}: {elapsed:.1f} s")
        overhead = cluster_costs(client, scene, points, normals, year)
    embree.close()
    truth = counts["exact, 1 process (2 threads)"]
    rows = []
    for name, runs in seconds.items():
        median = float(np.median(runs))
        rows.append(dict(tool=name, seconds=median, runs=runs, per_sun_s=median / len(suns),
                         queries_per_s=n * len(suns) / median, year_s=median / len(suns) * len(year),
                         sensors_count_differs=int(np.count_nonzero(counts[name] != truth)),
                         max_count_difference=float(np.abs(counts[name] - truth).max())))
    agreement = per_step_agreement(scene, suns, points, normals, eps, device)
    doc = dict(machine=run.machine(device), load_start=load_start, load_end=os.getloadavg(),
               scene=str(SCENE.name), triangles=len(scene.mesh.faces), spacing=args.spacing, sensors=n,
               grids={g.name: len(g.points) for g in grids}, suns_in_year=len(year), timed_suns=len(suns),
               every=args.every, rounds=args.rounds, batch=BATCH, rows=rows, agreement=agreement, cluster=overhead,
               prediction=predict(rows, overhead, len(year), n))
    report.save(args.out, "sun_hours-quick" if args.quick else "sun_hours", doc, markdown(doc))
    print(markdown(doc))
    return doc


def per_step_agreement(scene, suns, points, normals, eps, device) -> list[dict]:
    """Receivers whose mask differs between exact and Embree, on AGREEMENT_STEPS steps spread over ``suns``."""
    import peers

    bvh = peers.build_scene(scene.mesh.vertices, scene.mesh.faces)
    picks = np.linspace(0, len(suns) - 1, min(AGREEMENT_STEPS, len(suns))).astype(int)
    out = []
    for k in picks:
        exact = sc.shadow_mask(scene, suns[k], points, normals, device=device)
        embree = peers.shadow_mask(bvh, points, normals, suns[k], eps)
        differ = int(np.count_nonzero(exact != embree))
        elevation = float(np.degrees(np.arcsin(-suns[k].direction[1])))
        out.append(dict(step=int(k), elevation_deg=elevation, differ=differ, fraction=differ / len(points),
                        shadowed=float(exact.mean())))
    return out


def cluster_costs(client, scene, points, normals, year) -> dict:
    """Per-task overhead and transfer sizes on the LocalCluster (module docstring)."""
    noop_count = 200
    elapsed, _ = clock(lambda: client.gather(client.map(lambda i: i, range(noop_count), pure=False)))
    tiny = 40
    runs = {"local": lambda: sc.shadow_counts(scene, year[:tiny], points[:8], normals[:8], batch=1),
            "cluster": lambda: sc.shadow_counts(scene, year[:tiny], points[:8], normals[:8], batch=1, client=client)}
    for call in runs.values():      # warm-up: the kernels for 8 receivers built in every process
        call()
    local, remote = (clock(call)[0] for call in runs.values())
    scattered = len(pickle.dumps((scene.mesh, points, normals), protocol=5))
    start = time.perf_counter()
    [future] = client.scatter([(scene.mesh, points, normals)], broadcast=True, hash=False)
    scatter_s = time.perf_counter() - start
    client.cancel([future])
    return dict(noop_task_s=elapsed / noop_count, tiny_batches=tiny, tiny_local_s=local, tiny_cluster_s=remote,
                batch_overhead_s=(remote - local / 2) / tiny,   # the cluster's 2 workers share the local work
                scattered_bytes=scattered, scatter_2_workers_s=scatter_s,
                batch_lights_bytes=len(pickle.dumps(year[:BATCH], protocol=5)),
                batch_result_bytes=8 * len(points))


def predict(rows, overhead, lights: int, sensors: int) -> dict:
    """The year on W single-thread workers (W = 1 core each), from what the LocalCluster measured:

    - compute: the cluster's per-sun time on one worker, shared by W, plus the overhead of each batch;
    - reduce: the batches' counts summed on the workers in a binary tree (``PairwiseSum``): each sum
      moves one batch result between workers, W transfers at a time, then the tree's last log2 levels
      one after another; the client receives one array;
    - scatter: one copy of the scene and sensors to each worker from the client.
    Transfers at the LocalCluster's measured scatter rate (loopback, under the run's load)."""
    cluster = next(r for r in rows if r["tool"].startswith("exact, LocalCluster"))
    per_sun_one_worker = 2 * cluster["per_sun_s"]           # two workers ran it
    batches = -(-lights // BATCH)
    rate = overhead["scattered_bytes"] * 2 / max(overhead["scatter_2_workers_s"], 1e-9)   # bytes/s into workers
    transfer = overhead["batch_result_bytes"] / rate
    out = {}
    for workers in (2, 10, 100):
        compute = lights * per_sun_one_worker / workers + batches / workers * overhead["batch_overhead_s"]
        reduce = (batches - 1) / workers * transfer + np.log2(batches) * transfer + transfer
        scatter = workers * overhead["scattered_bytes"] / rate
        out[str(workers)] = dict(compute_s=compute, reduce_s=float(reduce), scatter_s=scatter,
                                 total_s=float(compute + reduce + scatter))
    return out


def markdown(doc: dict) -> str:
    lines = [f"# Sun hours on the city block: {doc['sensors']:,} sensors (spacing {doc['spacing']} m), "
             f"{doc['suns_in_year']:,} suns in the year", "",
             f"Timed on {doc['timed_suns']} suns (every {doc['every']}th of the year), median of {doc['rounds']} "
             f"interleaved rounds; the year extrapolated per sun. Load average at start / end: "
             f"{doc['load_start'][0]:.1f} / {doc['load_end'][0]:.1f} (2 cores, shared).", "",
             "| tool | seconds (timed suns) | per sun | M queries/s | year (extrapolated) | sensors whose count differs from exact |",
             "|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        lines.append(f"| {r['tool']} | {r['seconds']:.1f} | {r['per_sun_s'] * 1e3:.0f} ms | {r['queries_per_s'] / 1e6:.1f} | "
                     f"{r['year_s'] / 60:.1f} min | {r['sensors_count_differs']} (max {r['max_count_difference']:g}) |")
    lines += ["", "Agreement with Embree per time step (receivers whose mask differs):", "",
              "| step | sun elevation | differ | fraction | shadowed |", "|---|---|---|---|---|"]
    for a in doc["agreement"]:
        lines.append(f"| {a['step']} | {a['elevation_deg']:.1f}° | {a['differ']} | {a['fraction']:.2e} | {a['shadowed']:.3f} |")
    c = doc["cluster"]
    lines += ["", "LocalCluster costs:", "",
              f"- no-op task round trip (200 submitted at once): {c['noop_task_s'] * 1e3:.2f} ms per task",
              f"- {c['tiny_batches']} single-light batches on 8 sensors: {c['tiny_cluster_s']:.2f} s on the cluster, "
              f"{c['tiny_local_s']:.2f} s locally: {c['batch_overhead_s'] * 1e3:.1f} ms overhead per batch",
              f"- scattered once (mesh, sensors, normals): {c['scattered_bytes'] / 1e6:.1f} MB to each worker, "
              f"{c['scatter_2_workers_s']:.2f} s to 2 workers",
              f"- per batch of {doc['batch']} suns: {c['batch_lights_bytes']} B of lights out, "
              f"{c['batch_result_bytes'] / 1e6:.1f} MB of counts (summed on the workers; one array to the client)", "",
              "Predicted year (single-thread workers, one core each; model in docs/distributed.md):", "",
              "| workers | compute | reduce (tree of sums) | scatter | total |", "|---|---|---|---|---|"]
    for workers, p in doc["prediction"].items():
        lines.append(f"| {workers} | {p['compute_s']:.0f} s | {p['reduce_s']:.1f} s | {p['scatter_s']:.0f} s | "
                     f"{p['total_s']:.0f} s ({p['total_s'] / 60:.1f} min) |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
