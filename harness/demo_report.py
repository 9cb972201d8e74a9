"""The report folder of a bench session (``exohil demo --out``, ``exohil run --out``).

* ``summary.json``: :func:`~exohil.harness.session_report.summary`;
* ``summary.md``: the session (machine, device log, why it ended early, warnings), every
  measurement as a table, and the list of files;
* ``angles.png``: estimated and true angles (deg) over device time (s), shaded where the true
  elevation is below 20° (θ undefined with the arm hanging), as in the paper's figure;
* ``latency.png``: per-stage latency histograms (ms, log scale) on one monotonic clock, of
  every frame (the run's own fixed-size histograms), titled with the machine they ran on;
* ``hysteresis.png``: the sensor most correlated with the true elevation against it (mm vs
  deg), coloured by the elevation's direction of motion;
* ``arm.gif``, ``arm_0000k.png``: the simulated NAO (MuJoCo) beside the true human upper arm,
  sampled over the run (only with a MuJoCo robot and a reference);
* ``run.mcap``: the frames, estimates, commands and per-frame stage times
  (``run_recording``); its metadata entry ``latency_ms`` holds the summary's p50/p99/max per
  stage, ``robot_step`` included (the robot keeps only a histogram of its step times, so
  they are not per frame).

A run keeps per-frame rows only for its first and last frames (about a minute each, see
``pipeline.PipelineRun``), so memory stays bounded however long it runs: ``angles.png``,
``hysteresis.png`` and ``run.mcap`` show those frames (a left and a right column in
``angles.png`` when there is a gap between them; a note says so), while ``summary.json`` and
``latency.png`` cover every frame. ``exohil demo --record`` writes every frame as it goes.

Every file is written under a temporary name and renamed when complete. A report written
into a folder that holds an earlier one never mixes the two: the earlier report's files
(:func:`report_files_in`: the names above, ``arm_NNNNN.png`` included) are removed before
this run writes any, so one cut short (killed while drawing) leaves only this run's files;
nothing else in the folder is touched. Matplotlib draws with the Agg backend (files only).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from exohil.formats import strict_json
from exohil.formats.atomic import write_text, write_with
from exohil.harness.machine import machine
from exohil.harness.pipeline import PipelineRun
from exohil.harness.recording_plots import motion_direction
from exohil.harness.robot_stats import LogHistogram
from exohil.harness.run_recording import write_run_recording
from exohil.harness.session import SessionResult, latency_histograms
from exohil.harness.session_report import host_load_text

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: Elevation below which the plane of elevation θ is undefined (shaded), deg.
LOW_ELEVATION_DEG = 20.0
#: Arm pictures: still frames, and at most this many GIF frames (played in device time, at
#: 1 frame per second at the slowest).
ARM_FRAMES = 4
GIF_MAX_FRAMES = 120

Files = list[tuple[str, Path]]
#: The report's files whose names are fixed (arm_*.png are numbered).
REPORT_FILES = ("run.mcap", "summary.json", "summary.md", "angles.png", "latency.png",
                "hysteresis.png", "arm.gif")
#: The names of the numbered arm stills (``arm_00000.png`` ...).
ARM_STILL = re.compile(r"arm_[0-9]{5}\.png")


def report_files_in(out_dir: Path) -> list[Path]:
    """The files in ``out_dir`` that a report writes or replaces: :data:`REPORT_FILES` and the
    numbered arm stills, by those exact names (what else the folder holds is not a report's)."""
    named = [out_dir / name for name in REPORT_FILES]
    stills = sorted(p for p in out_dir.glob("arm_*.png") if ARM_STILL.fullmatch(p.name))
    return [p for p in named + stills if p.is_file() or p.is_symlink()]


def _save(figure: Figure, path: Path) -> Path:
    return write_with(path, lambda tmp: figure.savefig(tmp, format="png"))


def _figure(rows: int, cols: int = 1, height: float = 2.4) -> tuple[Figure, np.ndarray]:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8.0, height * rows), dpi=100, layout="constrained")
    return figure, np.atleast_1d(figure.subplots(rows, cols, squeeze=False).ravel())


def segments(run: PipelineRun) -> list[slice]:
    """The kept rows as runs of consecutive frames: one slice, or two (the run's first frames
    and its last) when frames between them were not kept."""
    if run.head >= run.retained:
        return [slice(0, run.retained)]
    return [slice(0, run.head), slice(run.head, run.retained)]


def plot_angles(result: SessionResult) -> Figure:
    """Estimated (solid) and true (dashed) angles over device time, one panel per angle (one
    column per segment of kept frames, see :func:`segments`)."""
    run, est = result.run, result.model.estimator
    angles = est.target.angles
    parts = segments(run)
    figure, axes = _figure(len(angles), len(parts))
    for c, part in enumerate(parts):
        t = run.device_time_s[part]
        truth = None if result.truth is None else result.truth[part]
        low = None
        if truth is not None and "shoulder_elv" in angles:
            low = truth[:, angles.index("shoulder_elv")] < LOW_ELEVATION_DEG
        for k, name in enumerate(angles):
            ax = axes[k * len(parts) + c]
            if low is not None:
                ax.fill_between(t, 0, 1, where=low, transform=ax.get_xaxis_transform(),
                                color="0.88", lw=0, label=f"elevation < {LOW_ELEVATION_DEG:g}°")
            if truth is not None:
                ax.plot(t, truth[:, k], "--", color="black", lw=1.2, label="true (mocap)")
            ax.plot(t, run.estimates[part, k], "-", color="tab:red", lw=1.0,
                    label=f"{est.kind} estimate")
            if c == 0:
                ax.set_ylabel(f"{name} (deg)")
            ax.grid(True, alpha=0.3)
        axes[(len(angles) - 1) * len(parts) + c].set_xlabel("device time (s)")
    axes[len(parts) - 1].legend(loc="upper right", fontsize=8)
    title = f"{est.target.joint}: estimated vs true angles"
    if len(parts) > 1:
        title += (f" (first {run.head} and last {run.retained - run.head} of {run.frames} "
                  "frames)")
    figure.suptitle(title)
    return figure


def _shown_from(hist: LogHistogram) -> float:
    """The smallest value ``hist`` shows: its first non-empty bin's lower edge (upper edge
    when that is 0)."""
    lower, upper, _ = hist.bins()
    return float(lower[0] if lower[0] > 0 else upper[0])


def plot_latency(result: SessionResult) -> Figure:
    """One histogram per stage interval (ms, log x, one shared range) of every frame, with
    p50/p99/max in the title; the robot's command → stepped delay from its own histogram when
    it ran. The histograms are the run's own (200 bins per decade), drawn on 60 bins."""
    from matplotlib.ticker import NullFormatter

    stages = {name.removeprefix("latency."): hist for name, (hist, _) in
              latency_histograms(result.run).items() if hist.count}
    robot = next((r.command_delay_ms for r in result.robots
                  if hasattr(r, "command_delay_ms") and r.command_delay_ms.count), None)
    if robot is not None:
        stages["robot_step (to MuJoCo stepped)"] = robot
    panels = len(stages)
    figure, axes = _figure((panels + 1) // 2, 2, height=2.2)
    low = max(1e-3, min((_shown_from(h) for h in stages.values()), default=1e-3))
    high = max((h.max for h in stages.values()), default=1.0)
    bins = np.logspace(np.log10(low) - 0.05, np.log10(max(high, low * 10)) + 0.05, 60)
    for ax, (name, hist) in zip(axes, stages.items(), strict=False):
        lower, upper, counts = hist.bins()
        centre = np.sqrt(np.maximum(lower, low) * np.maximum(upper, low))  # onto the 60 bins
        ax.hist(centre, bins=bins, weights=counts,
                color="tab:green" if hist is robot else "tab:blue")
        s = hist.summary(3)
        ax.set_title(f"{name}: p50 {s['p50']:.3g}  p99 {s['p99']:.3g}  max {s['max']:.3g} ms",
                     fontsize=8)
    for ax in axes[:panels]:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(bins[0], bins[-1])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("ms", fontsize=8)
        ax.set_ylabel("count", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[panels:]:
        ax.set_visible(False)
    figure.suptitle(f"per-stage latency, one monotonic clock (perf_counter)\non {machine()}",
                    fontsize=9)
    return figure


def plot_session_hysteresis(result: SessionResult) -> Figure | None:
    """The sensor most correlated with the true elevation against it, coloured by motion
    direction; None without a reference or an elevation angle."""
    est = result.model.estimator
    if result.truth is None or "shoulder_elv" not in est.target.angles:
        return None
    run = result.run
    phi = result.truth[:, est.target.angles.index("shoulder_elv")]
    ok = np.isfinite(phi)
    if ok.sum() < 10:
        return None
    # the direction of motion within each segment of consecutive frames
    direction = np.concatenate([motion_direction(run.device_time_s[part][ok[part]],
                                                 phi[part][ok[part]]) for part in segments(run)])
    phi, values = phi[ok], run.values[ok]
    if np.std(phi) == 0:  # the arm never moved: no loop to draw
        return None
    corr = [abs(np.corrcoef(values[:, j], phi)[0, 1]) if np.std(values[:, j]) > 0 else 0.0
            for j in range(values.shape[1])]
    j = int(np.argmax(corr))
    figure, (ax,) = _figure(1, height=5.0)
    for value, colour, label in ((0, "#b0b0b0", "still"), (1, "#d62728", "rising"),
                                 (-1, "#1f77b4", "falling")):
        chosen = direction == value
        if np.any(chosen):
            ax.scatter(phi[chosen], values[chosen, j], s=3, color=colour, linewidths=0,
                       alpha=0.6 if value else 0.3, label=f"elevation {label}", rasterized=True)
    ax.set_xlabel("true shoulder_elv (deg)")
    ax.set_ylabel(f"{est.sensor_names[j]} (mm, as received)")
    ax.set_title(f"{est.sensor_names[j]} vs elevation: hysteresis over the session")
    ax.grid(True, alpha=0.3)
    ax.legend(markerscale=4)
    return figure


#: The summary's notes on what its figures cover, with the label summary.md gives each.
_NOTES = (("device_lost", "device lost (the run ended before its time)"),
          ("ended_early", "ended early"),
          ("training_coverage_warning", "warning"), ("device_rate_warning", "warning"),
          ("sensor_rate_warning", "warning"))


def summary_markdown(s: dict[str, Any], files: Files) -> str:
    """``summary.md``: the session, every measurement, and where each file is."""
    lines = [f"# exohil session report ({s['finished_at']})", "",
             f"- target: {s['target']}", f"- model: {s['model']} ({s['model_kind']}, "
             f"{s['backend']})", "- frames: " + ", ".join(
                 f"{k.replace('_', ' ')} {'unknown (no device log)' if v is None else v}"
                 for k, v in s["frames"].items()),
             f"- wall time: {s['wall_s']} s",
             f"- machine (every time measured on it): {host_load_text(s)}"]
    if s["device_log"] is not None:
        lines.append("- device log: " + (", ".join(f"{k} {v}" for k, v in
                                                  sorted(s["device_log"].items()))
                                        or "nothing injected or lost"))
    lines += [f"- {label}: {s[key]}" for key, label in _NOTES if s.get(key)]
    lines += ["", "| measurement | value | unit | verdict | note |", "|---|---|---|---|---|"]
    for m in s["measurements"]:
        value = "–" if m["value"] is None else f"{m['value']:.4g}"
        lines.append(f"| {m['name']} | {value} | {m['unit']} | {m['verdict']} | "
                     f"{m['note'].replace('|', '/')} |")
    lines += ["", "## Files", ""] + [f"- {label}: `{path.name}`" for label, path in files]
    lines += [""] + [f"![{label}]({path.name})" for label, path in files
                     if path.suffix in (".png", ".gif") and not path.name.startswith("arm_")]
    return "\n".join(lines) + "\n"


def write_report(result: SessionResult, s: dict[str, Any], out_dir: Path) -> tuple[Files,
                                                                                    list[str]]:
    """Write the report folder (module doc) into ``out_dir`` (created).

    Returns (label, path) of every file written, in order, and notes on what was left out."""
    out_dir.mkdir(parents=True, exist_ok=True)
    # an earlier report's files, first: one left beside this run's would pass for this run's,
    # and a report cut short (killed while drawing) would mix the two
    for earlier in report_files_in(out_dir):
        earlier.unlink()
    est = result.model.estimator
    files: Files = []
    notes: list[str] = []
    run = result.run
    if not run.complete:
        notes.append(f"angles.png, hysteresis.png and run.mcap hold the first {run.head} and "
                     f"the last {run.retained - run.head} of the {run.frames} frames (bounded "
                     "memory); the summary and latency.png cover every frame")
    write_run_recording(
        out_dir / "run.mcap", result.run, est.sensor_names, est.target.joint, est.target.angles,
        {"generator": "exohil", "source": s["target"] or "", "model_sha256": s["model_sha256"],
         "latency_ms": json.dumps(s["latency_ms"], separators=(",", ":"))},
        result.sensor_rate_hz)
    files.append(("run recording", out_dir / "run.mcap"))
    files.append(("angles over time", _save(plot_angles(result), out_dir / "angles.png")))
    files.append(("latency histograms", _save(plot_latency(result), out_dir / "latency.png")))
    hysteresis = plot_session_hysteresis(result)
    if hysteresis is None:
        notes.append("no hysteresis.png: needs a reference with the true elevation")
    else:
        files.append(("hysteresis loop", _save(hysteresis, out_dir / "hysteresis.png")))
    files += _arm_pictures(result, out_dir, notes)
    md = out_dir / "summary.md"
    js = out_dir / "summary.json"
    listed = [*files, ("summary table", md), ("summary JSON", js)]
    write_text(md, summary_markdown(s, listed))
    write_text(js, strict_json.dumps(s, indent=2) + "\n")
    return listed, notes


def _arm_pictures(result: SessionResult, out_dir: Path, notes: list[str]) -> Files:
    from exohil.harness.robot_render import render_arm_frames, write_arm_animation

    trace = result.robot_trace
    if trace is None or trace.truth_deg is None:
        why = "no MuJoCo robot (--sink mujoco)" if trace is None else "no reference"
        notes.append(f"no arm.gif / arm_*.png: {why}")
        return []
    known = np.flatnonzero(np.all(np.isfinite(trace.truth_deg), axis=1))
    if known.size == 0:
        notes.append("no arm.gif / arm_*.png: no robot sample has a true pose")
        return []
    step = max(1, int(np.ceil(known.size / GIF_MAX_FRAMES)))
    shown = known[::step]
    span = float(trace.device_time_s[known[-1]] - trace.device_time_s[known[0]])
    # the frames play over the span they sample (25 fps at most, the trace's rate; 1 fps at
    # least, so a span over GIF_MAX_FRAMES seconds plays faster, in one second per frame)
    fps = min(25.0, max(1.0, shown.size / span)) if span > 0 else 1.0
    gif = write_arm_animation(trace.arm_samples(shown), out_dir / "arm.gif", fps=fps)
    stills = known[np.linspace(0, known.size - 1, ARM_FRAMES).astype(int)]
    frames = render_arm_frames(trace.arm_samples(np.unique(stills)), out_dir)
    return [("arm animation", gif)] + [("arm frame", p) for p in frames]
