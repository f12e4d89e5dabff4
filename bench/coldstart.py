"""Cold start: the first ``shadowcl render`` on a machine whose PoCL and PyOpenCL caches are empty.

    python bench/coldstart.py [--repeats 5] [--source DIR ...] [--trace] [--args ...]

Every run is a fresh interpreter running ``shadowcl render`` (the built-in demo scene unless ``--args``
says otherwise) with ``POCL_CACHE_DIR`` and ``XDG_CACHE_HOME`` (where PyOpenCL keeps its binaries)
pointing at new empty folders. Timed: wall time and CPU time (user + sys of the child and its
children, from ``os.wait4``). On this shared machine CPU time is the main figure: other jobs stretch
the wall time, while on a quiet machine wall is about CPU (the work is serial compiling).

``--source DIR`` (repeatable) runs the shadowcl of another checkout (``DIR/host`` and ``DIR/kernels``,
e.g. one extracted with ``git archive``), so that old and new are timed alternately in one run:
A, B, A, B ... and compared by medians. ``--trace`` adds, per run, every program build and every
kernel's first launch (per local size) with its CPU time: which compiles a render pays for. Every run
also counts what PoCL compiled, from its cache folder: one ``program.bc`` per program build and one
``.so`` per kernel work-group function (a kernel launched with several local sizes compiles once each).

Writes OUT/coldstart.{json,md}.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]
RESULTS = PROJECT / "bench" / "results"

# Run in the child: import the shadowcl of a source tree (its kernels as shadowcl.kernels, as setup.cfg
# installs them), optionally wrap builds and first launches to time them, then run the command line.
_CHILD = r"""
import json, resource, sys, time
source, trace, args = sys.argv[1], sys.argv[2] == "1", sys.argv[3:]
sys.path.insert(0, source + "/host")
import importlib.util
for name in ("kernels", "scenes"):
    spec = importlib.util.spec_from_file_location("shadowcl." + name, f"{source}/{name}/__init__.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["shadowcl." + name] = module
    spec.loader.exec_module(module)

def cpu():
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime

events = []
if trace:
    import pyopencl as cl
    build, call, seen = cl.Program.build, cl.Kernel.__call__, set()
    def timed_build(self, *a, **k):
        start = cpu()
        result = build(self, *a, **k)
        first_line = self.get_info(cl.program_info.SOURCE).split("\n", 1)[0]
        events.append(("build " + first_line.split(":")[0].strip("/* "), cpu() - start))
        return result
    def timed_call(self, queue, global_size, local_size, *a, **k):
        key = (self.function_name, local_size)
        if key in seen:
            return call(self, queue, global_size, local_size, *a, **k)
        seen.add(key)
        start = cpu()
        result = call(self, queue, global_size, local_size, *a, **k)
        queue.finish()   # PoCL compiles a kernel's work-group function at its first launch, not at clCreateKernel
        events.append((f"first launch {key[0]} local={key[1]}", cpu() - start))
        return result
    cl.Program.build, cl.Kernel.__call__ = timed_build, timed_call

from shadowcl.cli import main
sys.argv = ["shadowcl"] + args
code = main()
print("COLDSTART-EVENTS " + json.dumps(events))
# What PoCL compiled, from its cache: a program.bc per program build, a .so per work-group function
import os
names = [name for _, _, files in os.walk(os.environ["POCL_CACHE_DIR"]) for name in files]
print("COLDSTART-COMPILED " + json.dumps({"programs": names.count("program.bc"),
                                          "kernels": sum(name.endswith(".so") for name in names)}))
sys.exit(code or 0)
"""


def cold_run(python: str, source: Path, render_args: list[str], trace: bool) -> dict:
    """One render in a fresh interpreter with empty PoCL and PyOpenCL caches: wall and CPU seconds."""
    with tempfile.TemporaryDirectory(prefix="shadowcl-coldstart-") as scratch:
        env = dict(os.environ, POCL_CACHE_DIR=f"{scratch}/pocl", XDG_CACHE_HOME=f"{scratch}/xdg")
        env.pop("PYOPENCL_NO_CACHE", None)
        out = Path(scratch) / "out.png"
        command = [python, "-c", _CHILD, str(source), "1" if trace else "0", "render", *render_args, "--out", str(out)]
        start = time.perf_counter()
        process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        stdout, stderr = process.communicate()
        wall = time.perf_counter() - start
        # communicate() has reaped the child; its rusage (with its own children) is in RUSAGE_CHILDREN
        if process.returncode:
            raise RuntimeError(f"render failed ({process.returncode}) with {source}:\n{stderr}")
    events, compiled = [], {}
    for line in stdout.splitlines():
        if line.startswith("COLDSTART-EVENTS "):
            events = json.loads(line.split(" ", 1)[1])
        elif line.startswith("COLDSTART-COMPILED "):
            compiled = json.loads(line.split(" ", 1)[1])
    stages = next((line for line in stdout.splitlines() if line.startswith("times:")), "")
    return {"wall": wall, "events": events, "compiled": compiled, "stages": stages}


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--source", type=Path, action="append",
                        help="a shadowcl source tree to time (repeatable; default: this checkout)")
    parser.add_argument("--label", action="append", help="a name per --source (default: the folder)")
    parser.add_argument("--trace", action="store_true", help="time every build and first kernel launch")
    parser.add_argument("--args", nargs=argparse.REMAINDER, default=[], help="arguments after 'shadowcl render'")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    sources = [path.resolve() for path in (args.source or [PROJECT])]
    labels = args.label or [path.name for path in sources]
    if len(labels) != len(sources):
        parser.error("--label: give one per --source")

    runs: dict[str, list[dict]] = {label: [] for label in labels}
    for repeat in range(args.repeats):
        for label, source in zip(labels, sources):   # alternating: load changes hit every source alike
            before = children_cpu()
            run = cold_run(sys.executable, source, args.args, args.trace)
            run["cpu"] = children_cpu() - before
            runs[label].append(run)
            print(f"{label} run {repeat + 1}: cpu {run['cpu']:.2f} s, wall {run['wall']:.2f} s, compiled "
                  f"{run['compiled'].get('programs')} programs, {run['compiled'].get('kernels')} kernels; {run['stages']}")
            for what, seconds in run["events"]:
                print(f"    {what:56s} cpu {seconds:.3f} s")

    summary = {label: {"cpu_median": statistics.median(r["cpu"] for r in rs),
                       "cpu_min": min(r["cpu"] for r in rs),
                       "wall_median": statistics.median(r["wall"] for r in rs),
                       "wall_min": min(r["wall"] for r in rs),
                       "compiled": rs[0]["compiled"]} for label, rs in runs.items()}
    load = os.getloadavg()
    result = {"python": sys.version.split()[0], "machine": platform.machine(), "cpus": os.cpu_count(),
              "load_average_after": load, "repeats": args.repeats, "render_args": args.args,
              "summary": summary, "runs": runs}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "coldstart.json").write_text(json.dumps(result, indent=1) + "\n")
    lines = [f"# Cold start: first `shadowcl render {' '.join(args.args)}` with empty PoCL and PyOpenCL caches",
             "", f"{args.repeats} runs per source, alternating; load average after the run "
             f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on {os.cpu_count()} CPUs (wall is stretched by it, "
             "CPU time much less).", "",
             "| source | CPU median (s) | CPU min (s) | wall median (s) | wall min (s) | programs, kernels compiled |",
             "|---|---|---|---|---|---|"]
    for label, row in summary.items():
        lines.append(f"| {label} | {row['cpu_median']:.2f} | {row['cpu_min']:.2f} | {row['wall_median']:.2f} | "
                     f"{row['wall_min']:.2f} | {row['compiled'].get('programs')}, {row['compiled'].get('kernels')} |")
    if args.trace:
        lines += ["", "Traced builds and first launches (median CPU seconds over the runs; - : not in that source):", "",
                  "| event | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
        for what in dict.fromkeys(what for rs in runs.values() for r in rs for what, _ in r["events"]):
            cells = []
            for rs in runs.values():
                seconds = [dict(r["events"]).get(what) for r in rs]
                seconds = [x for x in seconds if x is not None]
                cells.append(f"{statistics.median(seconds):.3f}" if seconds else "-")
            lines.append(f"| {what} | " + " | ".join(cells) + " |")
        totals = [statistics.median(sum(seconds for _, seconds in r["events"]) for r in rs) for rs in runs.values()]
        lines.append("| all of them (median of the runs' sums) | " + " | ".join(f"{t:.2f}" for t in totals) + " |")
    (args.out / "coldstart.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
