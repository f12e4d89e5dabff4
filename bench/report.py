"""Reports of a bench run's results document: markdown table, speed-against-error plot, comparison."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

from peers import PEER, PEERS

def to_json(value):
    """JSON encoder fallback for NumPy scalars and arrays in method statistics."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def save(folder: Path, stem: str, doc: dict, text: str, plot=None) -> None:
    """Write ``stem``.json (the results document), ``stem``.md (``text``) and, given ``plot(doc, path)``,
    ``stem``.png into ``folder``: every bench's results in the same three files."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=to_json))
    (folder / f"{stem}.md").write_text(text)
    if plot is not None:
        plot(doc, folder / f"{stem}.png")


AGREEMENT_BAR = 2e-5  # exact and each peer differ on at most this fraction of receivers
THROUGHPUT_BAR = 1.0  # exact's one-shot throughput at least the fastest peer's (Mitsuba 3, Open3D, Embree)
# a row's times under their names since the public-call bench (issue 11), and before it
TIMES = {"prepare_s": ("prepare_s",), "query_s": ("query_s", "classify_s"), "oneshot_s": ("oneshot_s", "total_s")}


def time_of(row: dict, key: str):
    """``row``'s median of ``key`` (a key of :data:`TIMES`), in a results document of either schema."""
    return next(row[k] for k in TIMES[key] if k in row)


def _cell(value, digits: int = 3) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1e5 else f"{value:.0f}"
    return str(value)


def case_key(row: dict) -> tuple:
    """(scene, light, with normals) of a row: its case (rows of runs before the normals option had normals)."""
    return row["scene"], row["light"], row.get("normals", True)


def judged(disputes: dict | None, name: str) -> str:
    """What the float64 reference said of a peer's disagreements with exact (run.judge_disputes), or ''."""
    if not disputes:
        return ""
    return (f"; the float64 reference on {disputes['judged']} of them: exact right on {disputes['truth_right']}, "
            f"{name} right on {disputes['row_right']}, {disputes['within_rounding']} within float32 rounding")


def bars(doc: dict) -> list[str]:
    """The bars per case: exact's mask differences with each peer, and its one-shot throughput against
    the fastest peer's."""
    if doc["settings"]["truth_method"] != "exact":
        return ["Bars not assessed: the truth is Embree's mask (the exact method is not available)."]
    lines = []
    for (scene, light, normals), group in itertools.groupby(doc["rows"], key=case_key):
        group = list(group)
        light = f"{light} {'with' if normals else 'without'} normals"
        for name in dict.fromkeys(r["method"] for r in group if r["method"] in PEERS):
            peer = next(r for r in group if r["method"] == name)
            fraction = peer["wrong"] / peer["receivers"]
            verdict = "met" if fraction <= AGREEMENT_BAR else "MISSED"
            lines.append(f"{scene} light {light}: exact and {name} differ on {peer['wrong']} of {peer['receivers']} "
                         f"receivers ({fraction:.2g}; {peer['false_shadow']} {name}-only shadow, "
                         f"{peer['false_light']} exact-only shadow){judged(peer.get('disputes'), name)}; "
                         f"bar <= {AGREEMENT_BAR:g}: {verdict}")
        for row in group:
            if row["method"] == "exact" and row["vs_peer"] is not None:
                verdict = "met" if row["vs_peer"] >= THROUGHPUT_BAR else "MISSED"
                lines.append(f"{scene} light {light}: {row['label']} (one-shot sc.shadow_mask) runs at "
                             f"{row['vs_peer']:.2f}x the fastest peer ({row['fastest_peer']}, prepare + classify); "
                             f"bar >= {THROUGHPUT_BAR}x: {verdict}")
    return lines


def markdown(doc: dict, plot_name: str | None = None) -> str:
    """The run as markdown: machine, settings, cases, one table row per setting, the bars, the plot."""
    m, s = doc["machine"], doc["settings"]
    versions = ", ".join(f"{k} {v}" for k, v in m["versions"].items() if v)
    lines = [
        f"# shadowcl bench, {doc['date']}",
        "",
        f"- Machine: {m['cpu']}, {m['cores']} cores; OpenCL device {m['opencl_device']} ({m['opencl_platform']})",
        f"- Versions: {versions}; Python {m['python']}",
        f"- Truth: {s['truth']}",
        f"- Receivers: {s['receivers']['ground']} + {s['receivers']['model']} per scene (seed {s['seed']}); "
        f"{s['timing']}, {s['repeats']} repeats",
        f"- Peer: {s['peer']}",
        f"- Host memory: {doc['rows'][0]['memory_method'] if doc['rows'] else ''}",
        *(f"- Skipped {name}: {why}" for name, why in s["skipped"].items()),
        *(f"- Case {note}" for note in doc["cases"]),
        *(f"- FAILED {f['scene']} light {f['light']} {f['label']}: {f['error']}" for f in doc["failed"]),
        "",
        "| scene | light | normals | setting | one-shot ms | interleaved ms | prepare ms | query ms | M recv/s "
        "| M recv/s (query) | host share | false shadow | false light | error % | vs fastest peer | host MiB | device MiB |",
        "|---|---|---|---|" + "---:|" * 13,
    ]
    for r in doc["rows"]:
        interleaved = r.get("oneshot_interleaved_s")
        cells = [r["scene"], r["light"], "yes" if r.get("normals", True) else "no", r["label"], 1e3 * r["oneshot_s"],
                 None if interleaved is None else 1e3 * interleaved, 1e3 * r["prepare_s"], 1e3 * r["query_s"],
                 r["receivers_per_s"] / 1e6, r["receivers_per_s_query"] / 1e6, r["host_share"], r["false_shadow"],
                 r["false_light"], r["error_percent"], r["vs_peer"], r["host_peak_mib"], r["device_mib"]]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    lines += ["", *(f"- {line}" for line in bars(doc))]
    for row in doc["rows"]:
        if row["method"] == PEER and row["method_stats"]:
            stages = ", ".join(f"{key[:-2]} {1e3 * value:.0f} ms" for key, value in row["method_stats"].items())
            lines.append(f"- {row['scene']} light {row['light']}, {row['label']}, stages of the last run: {stages}")
    if plot_name:
        lines += ["", f"![speed against error]({plot_name})"]
    return "\n".join(lines) + "\n"


def plot(doc: dict, path) -> None:
    """Speed (receivers/s, prepare included) against error (%), log-log, one panel per case.

    A setting with no error is drawn at half a receiver's worth of error, at the panel's left edge.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [(key, list(group)) for key, group in itertools.groupby(doc["rows"], key=case_key)]
    figure, axes = plt.subplots(1, max(len(cases), 1), figsize=(6 * max(len(cases), 1), 4.5), squeeze=False)
    methods = sorted({r["method"] for r in doc["rows"]})
    style = {name: (marker, f"C{i}") for i, (name, marker) in enumerate(zip(methods, itertools.cycle("os^Dv<>p*h")))}
    for axis, ((scene, light, normals), rows) in zip(axes[0], cases):
        light = f"{light}, {'with' if normals else 'no'} normals"
        floor = 100 * 0.5 / rows[0]["receivers"]
        for name in methods:
            mine = [r for r in rows if r["method"] == name]
            if not mine:
                continue
            x = [max(r["error_percent"], floor) for r in mine]
            y = [r["receivers_per_s"] for r in mine]
            marker, color = style[name]
            axis.scatter(x, y, marker=marker, color=color, label=name)
            for r, xi, yi in zip(mine, x, y):
                text = r["label"][len(name):].strip()
                if text:
                    axis.annotate(text, (xi, yi), textcoords="offset points", xytext=(4, 3), fontsize=7)
        axis.axvline(floor, color="0.8", linestyle=":", zorder=0)
        axis.set_xlim(floor / 2, max([1000 * floor] + [2 * r["error_percent"] for r in rows]))
        axis.set(xscale="log", yscale="log", title=f"{scene}, light {light} ({rows[0]['receivers']} receivers)",
                 xlabel="misclassified receivers, % (dotted: none)", ylabel="receivers/s, prepare included")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8)
    figure.suptitle(f"shadowcl: speed against error ({doc['machine']['cpu']}, {doc['date'][:10]})", fontsize=10)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def compare(doc: dict, old: dict) -> str:
    """Markdown table of new/old time ratios (below 1 is faster now) and the error then and now,
    for the settings both runs share."""
    before = {(*case_key(r), r["label"]): r for r in old["rows"]}
    counts = {(r["scene"], r["receivers"]) for r in doc["rows"]} ^ {(r["scene"], r["receivers"]) for r in old["rows"]}
    warning = [f"Receiver counts differ between the runs: {sorted(counts)}", ""] if counts else []
    lines = [f"Compared with the run of {old['date']} ({old['machine']['cpu']}):", "", *warning,
             "| scene | light | setting | prepare new/old | query new/old | one-shot new/old | error % old → new |",
             "|---|---|---|---:|---:|---:|---|"]
    for r in doc["rows"]:
        o = before.get((*case_key(r), r["label"]))
        if o is not None:
            ratios = [time_of(r, k) / time_of(o, k) if time_of(o, k) else None for k in TIMES]
            lines.append(f"| {r['scene']} | {r['light']} | {r['label']} | "
                         + " | ".join(_cell(x) for x in ratios)
                         + f" | {_cell(o['error_percent'])} → {_cell(r['error_percent'])} |")
    return "\n".join(lines) + "\n"
