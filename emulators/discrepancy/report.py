"""Outputs of a discrepancy run: ``discrepancy.json``, ``report.md`` with two plots, and the
calibrated suit profile ``suit_profile.toml``. Every file is first written under a temporary
name in the output folder, and they are renamed into place only once all of them are
complete, so a crash or Ctrl-C never leaves a half-written file under a final name, nor some
files of this run beside others of an earlier run in the same folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import cast

import numpy as np

from exohil.emulators.discrepancy.data import (
    FRAME_COUNTER,
    MOCAP_CUTOFFS_HZ,
    invalid_words,
    spike_counts,
)
from exohil.emulators.discrepancy.localise import (
    SAME_POSE_DEG,
    SIGNATURES,
    SIMULATED_SHARE,
    STEP_FLATNESS,
    STEP_SIGMAS,
    STEP_WINDOW_S,
    motion,
)
from exohil.emulators.discrepancy.profile import calibrated_suit, profile_dict, to_toml
from exohil.emulators.discrepancy.timing import (
    after_effects_words,
    clock_words,
    filter_words,
    skew_words,
)
from exohil.emulators.discrepancy.workers import forked_map, workers_for
from exohil.emulators.discrepancy.workflow import (
    DRIFT_KEPT_NOTED,
    Outcome,
    drift_kept_words,
    map_words,
    rail_words,
    resampled_words,
    stamped_words,
)
from exohil.emulators.protocols import ANGLE_NAMES
from exohil.formats.atomic import temporary_name, write_bytes

OUTPUT_NAMES = ("discrepancy.json", "report.md", "residual_time.png", "residual_angle.png",
                "suit_profile.toml")


def _main_angle(outcome: Outcome) -> int:
    """The angle with the widest recorded range (the x axis of the angle plot)."""
    a = outcome.trial.angles[outcome.trial.valid]
    return int(np.argmax(np.ptp(a, axis=0)))


#: Window of the moving RMS drawn over the residual against time, s.
RMS_WINDOW_S = 2.0


def _moving_rms(x: np.ndarray, window: int) -> np.ndarray:
    """RMS of the finite values of x (N,) in a centred window of ``window`` frames; NaN
    where the window holds none."""
    finite = np.isfinite(x)
    kernel = np.ones(window)
    total = np.convolve(np.where(finite, x, 0.0) ** 2, kernel, mode="same")
    count = np.convolve(finite.astype(float), kernel, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(total / count)


def plots(outcome: Outcome, workers: int | None = None) -> dict[str, bytes]:
    """The two plots as PNG bytes, by file name, each drawn in a forked process of its own
    where there are two CPUs (drawing is a few seconds of one core each; the figures are
    the same either way)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401  (loaded once, before the processes fork)

    draw = {"residual_time.png": _time_plot, "residual_angle.png": _angle_plot}
    names = list(draw)
    pngs = forked_map(lambda name: draw[name](outcome), names, workers_for(workers))
    return dict(zip(names, pngs, strict=True))


def _label(text: str) -> str:
    """``text`` as a plot label drawn as written: matplotlib reads what stands between two
    dollar signs as math (a sensor named '$\\frac$' fails to draw)."""
    return text.replace("$", r"\$")


def _png(fig) -> bytes:  # noqa: ANN001  (a matplotlib Figure: not imported at module level)
    """The figure as PNG bytes (90 dpi); the figure is closed."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def _time_plot(outcome: Outcome) -> bytes:
    """The held-out residual of each sensor against time, before and after, with its RMS
    over ``RMS_WINDOW_S``."""
    import matplotlib.pyplot as plt

    trial = outcome.trial
    s = trial.n_sensors
    fig, axes = plt.subplots(s, 1, figsize=(10, 1.8 * s + 1), sharex=True, squeeze=False,
                             layout="constrained")
    window = max(1, int(round(RMS_WINDOW_S * trial.rate_hz)))
    for j, ax in enumerate(axes[:, 0]):
        for fit, light, dark, label in ((outcome.before, "0.8", "0.3", "before"),
                                        (outcome.after, "#f4a6a6", "C3", "after")):
            ax.plot(trial.t, fit.residual[:, j], lw=0.5, color=light)
            ax.plot(trial.t, _moving_rms(fit.residual[:, j], window), lw=1.2, color=dark,
                    label=label)
        ax.set_ylabel(_label(f"{trial.sensor_names[j]} [{trial.units}]"))
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("held-out residual (measured − simulated) before and after the added "
                 f"effects; dark: its RMS over {RMS_WINDOW_S:g} s")
    return _png(fig)


def _angle_plot(outcome: Outcome) -> bytes:
    """The held-out residual of each sensor against the widest-ranging angle, before and
    after, coloured by the direction of the sensor's motion (at most 20,000 frames)."""
    import matplotlib.pyplot as plt

    trial = outcome.trial
    s = trial.n_sensors
    k = _main_angle(outcome)
    direction = motion(trial, outcome.inputs.static)["direction"]
    stride = max(1, trial.n // 20000)
    fig, axes = plt.subplots(s, 2, figsize=(10, 1.8 * s + 1), sharex=True, squeeze=False,
                             layout="constrained")
    for j in range(s):
        for col, (label, fit) in enumerate((("before", outcome.before),
                                            ("after", outcome.after))):
            ax = axes[j, col]
            for sign, colour, name in ((1, "tab:red", "rising"), (-1, "tab:blue", "falling"),
                                       (0, "0.6", "still")):
                sel = (direction[:, j] == sign) & trial.valid
                sel[np.arange(trial.n) % stride != 0] = False
                ax.plot(trial.angles[sel, k], fit.residual[sel, j], ".", ms=1, color=colour,
                        label=name)
            if j == 0:
                ax.set_title(label)
            if col == 0:
                ax.set_ylabel(_label(f"{trial.sensor_names[j]} [{trial.units}]"))
    axes[0, 1].legend(loc="upper right", fontsize=8, markerscale=6)
    for ax in axes[-1]:
        ax.set_xlabel(_label(f"{trial.angle_names[k]} [deg]"))
    fig.suptitle("held-out residual against angle, by direction of the sensor's motion")
    return _png(fig)


def _blocks(count: int) -> str:
    """A count of held-out blocks in words: "1 block", "7 blocks"."""
    return f"{count} block" + ("" if count == 1 else "s")


def _refined_count(refined: dict, units: str) -> str:
    """The sentence on the count a drift was named on (its refined form, before the map's
    degree was chosen again)."""
    on = refined["significant_on_sensors"]
    alone = f"; on {', '.join(on)} alone it passed both rules against its own noise" if on else ""
    return (f"The drift it would become left a held-out gap of {refined['heldout_gap']:.4g} "
            f"{units} and improved {_blocks(refined['blocks_improved'])} (rule 2 needs "
            f"{refined['blocks_needed']}){alone}.")


def _clock_lines(summary: dict, u: str) -> list[str]:
    """The clock offset's and the clock rate's evidence (``clock_offset`` and
    ``clock_skew`` of the JSON) as a paragraph each; none where the readings do not run
    ahead of the motion capture, nor their lead change with time. Then what the final
    model's screens found (``timing_after_effects``) where it was not read so."""
    lines = []
    for key, say in (("clock_offset", clock_words), ("clock_skew", skew_words)):
        if summary.get(key) is not None:
            words = say(summary[key], u)
            lines += [_sentence(words) + ".", ""]
    for key, found in summary.get("timing_after_effects", {}).items():
        if found is not None and not (found["applied"] and found["run_again"]["kept"]):
            lines += [f"With the effects in place {after_effects_words(key, found, u)}.", ""]
    return lines


def _sentence(words: str) -> str:
    """``words`` with its first letter a capital (the rest as written: sensor names keep
    their case)."""
    return words[:1].upper() + words[1:]


def _placed_words(summary: dict) -> str:
    """How the frames were put on the grid and timed, where that is not a plain frame
    counter with the times recorded: a parenthesis, or nothing."""
    words = []
    if summary["frames_placed_by"] != FRAME_COUNTER:
        words.append(f"placed by {summary['frames_placed_by']}")
    if summary["frame_times"] == "steady rate":
        words.append(f"{stamped_words(summary['frame_time_scatter_s'])}, so read at steady times")
    return f" ({'; '.join(words)})" if words else ""


def _filter_sentence(summary: dict, units: str) -> str:
    """How the motion capture was read, as a sentence of its own; where its angles were
    low-passed at the lowest cutoff and stops were named, what such angles' noise can be
    named (discrepancy-limitations.md: 2° of white noise per sample, low-passed at 6 Hz,
    was named saturation on 3 of 3 clean suits)."""
    chosen = summary["mocap_filter"]
    line = f" {_sentence(filter_words(chosen, units))}."
    lowest = min(MOCAP_CUTOFFS_HZ)
    if (chosen is not None and chosen["applied"] and chosen["low_pass_hz"] == lowest
            and "saturation" in summary["effects"]):
        line += (f" Angles noisy enough to be low-passed at {lowest:g} Hz can be read as "
                 "stops: the map, fitted to noisy angles, overshoots the readings at the ends "
                 "of their range, where stops clip it (2° of white angle noise per sample was "
                 "named saturation on 3 of 3 clean suits, 1° on 1 of 3), so weigh the "
                 "saturation named here against the motion capture's noise.")
    return line


def _unused(value: object) -> bool:
    """A parameter of a part of the term the model does not use (None or [] in the JSON)."""
    return value is None or (isinstance(value, list | tuple) and not value)


def _figure(value: object) -> str:
    """A parameter or statistic as the report prints it: numbers to 4 significant digits,
    lists joined by commas, — where nothing was measured or set."""
    if _unused(value):
        return "—"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int | float):
        return f"{value:.4g}"
    if isinstance(value, list | tuple):
        return ", ".join(_figure(v) for v in value)
    return str(value)


#: Parameters (``steps[].params`` of the JSON) that hold one entry per sensor.
PER_SENSOR_PARAMS = frozenset({
    "loop_width", "gain", "quadratic_gain_per_unit", "centre", "rate_per_s", "change",
    "mean_rate_per_s", "stops", "softness", "shape", "lower", "upper"})
#: Parameters left to the JSON: the hysteresis term's play operators (a row per sensor of
#: as many thresholds and weights as the model has plays, and of the weights of each power
#: of the plays' level).
JSON_ONLY_PARAMS = frozenset({"play_thresholds", "play_thresholds_deg", "weights",
                              "level_weights"})


#: What each parameter of ``steps[].params`` means, in the order the report explains them
#: (a per-sensor one is a column of its step's table, the others follow the step's title).
PARAMETERS = {
    "on": "what the loop's plays act on: the reading (a loop in the static prediction) or "
          "the angles (a loop in the pose, read through the map's slope in each angle)",
    "angles": "the angles whose plays make a loop in the pose",
    "loop_width": "the falling branch minus the rising branch after an excursion wider than "
                  "the widest play, sensor units, at the middle of the sensor's range (plays "
                  "on the reading) or at the map's median slope in each angle, every angle "
                  "reversing at once (plays on the angles): positive where the reading is "
                  "higher on the way down than on the way up (it trails its input), negative "
                  "where lower",
    "level_degree": "the loop's degree in the level: 1, as wide at every level "
                    "(Prandtl–Ishlinskii); 2 or 3, a width that changes along the range",
    "tau_s": "time constant(s), s: of each low-pass of the stretch (creep), or of the "
             "reading's first-order low-pass (lag)",
    "build_recover_s": "a creep that builds and recovers at different rates: its build and "
                       "recovery time constants, s",
    "hold_grow_recover_s": "a creep that flows only while the joint holds still: its growth "
                           "(during holds) and recovery (while moving) time constants, s",
    "gain": "per sensor, the weight of each creep state (one per time constant, then the "
            "build/recover and hold states; a share of the static prediction, no unit), or "
            "of a rate limit's column",
    "quadratic_gain_per_unit": "the weight of each low-passed (ŝ − centre)², per sensor "
                               "unit: a creep whose driver grows with the square of the "
                               "stretch",
    "centre": "the middle of the static prediction's range (p1–p99), where that quadratic "
              "driver is centred, sensor units",
    "model": "which lag: first_order (a low-pass), delay, first_order_delay (a low-pass, then "
             "a delay) or rate_limit (a slew-rate limit)",
    "delay_s": "the pure delay, s",
    "sensors": "the sensors the lag acts on",
    "rate_per_s": "the most the reading changes per second under a slew-rate limit, sensor "
                  "units/s (— : no limit)",
    "basis": "the drift's functions of time: a Legendre polynomial or piecewise linear",
    "degree": "the drift polynomial's degree",
    "intervals": "the piecewise-linear drift's even intervals over the recording",
    "knots_every_s": "the spacing of its knots, s",
    "change": "the drift from the first frame to the last, sensor units",
    "mean_rate_per_s": "that change over the recording's length, sensor units/s",
    "stops": "lower, upper: the level where the reading stops following the pose, sensor "
             "units (— : no stop at that end)",
    "softness": "lower, upper: how far beyond the knee the bend's asymptote lies, sensor "
                "units (0: a hard stop)",
    "shape": "lower, upper: the soft knee's form, tanh or exp (an exponential approach)",
    "lower": "the lowest reading the model predicts, sensor units",
    "upper": "the highest reading the model predicts, sensor units",
}


def _meaning_lines(steps: list[dict]) -> list[str]:
    """What the parameters of ``steps`` (and of what they chose again) mean, those shown."""
    shown = {k for step in steps
             for params in [step["params"], *step["evidence"].get("refitted", {}).values()]
             for k, v in params.items() if k not in JSON_ONLY_PARAMS and not _unused(v)}
    rows = [f"| {k} | {meaning} |" for k, meaning in PARAMETERS.items() if k in shown]
    return ["", "| parameter | meaning |", "|---|---|", *rows] if rows else []


def _parameter_block(title: str, params: dict, sensors: list[str]) -> list[str]:
    """One effect's parameters: those of the whole term after ``title`` (a part of the term
    the model does not use, None or [] in the JSON, left out), those of each sensor in a
    table with a row per sensor."""
    params = {k: v for k, v in params.items() if k not in JSON_ONLY_PARAMS}
    per_sensor = [k for k, v in params.items() if k in PER_SENSOR_PARAMS
                  and isinstance(v, list) and len(v) == len(sensors)]
    whole = "; ".join(f"{k} {_figure(v)}" for k, v in params.items()
                      if k not in per_sensor and not _unused(v))
    lines = ["", title + (f": {whole}." if whole else ".")]
    if per_sensor:
        lines += ["", "| sensor | " + " | ".join(per_sensor) + " |",
                  "|---" * (len(per_sensor) + 1) + "|"]
        lines += [f"| {name} | " + " | ".join(_figure(params[k][j]) for k in per_sensor)
                  + " |" for j, name in enumerate(sensors)]
    return lines


def _parameter_lines(summary: dict) -> list[str]:
    """Each step's fitted parameters, and those of the earlier effects that step chose
    again with its own in place (``evidence.refitted``)."""
    if not summary["steps"]:
        return []
    lines = ["", "## Parameters of each step", "",
             f"Sensor units ({summary['units']}) unless the name says otherwise; every figure, "
             "and the hysteresis term's play operators, in full in `discrepancy.json`. Where "
             "a step chose an earlier effect's parameters again with its own in place "
             "(`evidence.refitted`), they follow its own."]
    sensors = summary["sensors"]
    for i, step in enumerate(summary["steps"], start=1):
        lines += _parameter_block(f"Step {i}, {step['effect']}", step["params"], sensors)
        for kind, params in step["evidence"].get("refitted", {}).items():
            lines += _parameter_block(f"Step {i} chose {kind} again", params, sensors)
    return lines + _meaning_lines(summary["steps"])


def _signature_lines(steps: list[dict]) -> list[str]:
    """The signatures of the residual each step started from, a column per step, with
    what each points to."""
    if not steps:
        return []
    names = [k for k in SIGNATURES if k in steps[0]["evidence"]["signature"]]
    lines = ["", "## Signatures in the residual each step started from", "",
             "| signature | " + " | ".join(f"step {i} ({s['effect']})"
                                          for i, s in enumerate(steps, start=1))
             + " | points to |", "|---" * (len(steps) + 2) + "|"]
    for name in names:
        lines.append(f"| {name} | " + " | ".join(
            _figure(s["evidence"]["signature"].get(name)) for s in steps)
            + f" | {SIGNATURES[name]} |")
    return lines


#: MoBL-ARMS shoulder angles (docs/conventions.md) and what each adds to the pose.
SHOULDER_ANGLES = {"elv_angle": "the plane of elevation, without which the arm's direction "
                                "is not known once it rises",
                   "shoulder_elv": "the elevation",
                   "shoulder_rot": "the axial rotation, which changes the path of a tendon "
                                   "that wraps the upper arm"}


def _remainder_lines(summary: dict) -> list[str]:
    """What the final model leaves: within the noise in one line, or beyond it with what it
    may be (:func:`~.rules.remainder`)."""
    left, u = summary["remainder"], summary["units"]
    gap, floor = summary["gap_after"], summary["noise_floor"]
    if left["gap_over_floor"] is None:
        return []
    variances = left["noise_variances"]
    beyond = ("nothing beyond the noise" if variances <= 0 else
              f"{f'{variances:,.0f}' if variances >= 1000 else f'{variances:.3g}'} noise "
              "variances beyond the noise")
    head = (f"{gap:.4g} {u}, {left['gap_over_floor']:.3g}× the noise floor ({floor:.4g} {u}): "
            f"{beyond}")
    model = "the effects named" if summary["steps"] else "the calibrated static map"
    if not left["beyond_noise"]:
        return ["", f"What remains is noise: with {model} the model leaves {head}, under the "
                    "one noise variance an effect must remove to be named."]
    sensors = left["beyond_noise_sensors"]
    where = ("every sensor" if len(sensors) == len(summary["sensors"])
             else ", ".join(sensors) if sensors else "no sensor alone")
    lines = ["", "## What remains", "",
             f"With {model} the model leaves {head}, more than the one noise variance an "
             f"effect must remove to be named; beyond its own noise on {where}. "
             + ("None of the five effects explains it (each candidate of the last step "
                "stayed under the noise, improved too few held-out blocks or lowered the "
                "error only from frame to frame: \"Not added\" below)."
                if summary["not_added"] else "All five effects are in the model."),
             ""]
    shoulder = [f"`{name}`, {meaning}" for name, meaning in SHOULDER_ANGLES.items()
                if summary["joint"] == "shoulder" and name not in summary["angles"]]
    # another joint than the shoulder is analysed only where the recording has no shoulder
    # stream (the joint with the most samples): the suit may be worn elsewhere
    joint = ("" if summary["joint"] == "shoulder" else
             f" (only the {summary['joint']}'s " + ", ".join(f"`{a}`" for a in summary["angles"])
             + (" was" if len(summary["angles"]) == 1 else " were")
             + " analysed, the recording holding no shoulder angles: a suit worn on "
             "another joint follows that joint's angles)")
    return lines + [
        "What it is, the recording alone cannot say. It may be: the calibrated map's form "
        "falling short of this suit's geometry; angles the readings follow that are not "
        "recorded" + (" (the recording has no moving " + "; no moving ".join(shoulder) + ")"
                      if shoulder else joint)
        + "; the suit shifting on the skin or slipping over a bony prominence; the movement's "
        "history, through an effect outside the five or one of them in a form the candidates "
        "do not follow; noise the floor does not count (the floor is the sensors' "
        "frame-to-frame noise: slower noise, and the motion capture's angle noise seen "
        "through the suit, are not in it). \"Where the residual was\" and \"Sudden changes "
        "of the reading\" below show where it lies."]


def _before_after(head: str, rows: list[tuple[str, float | None, float | None]]
                  ) -> list[str]:
    """A before/after table of residual RMS, the largest before in bold."""
    largest = max((b for _, b, _ in rows if b is not None), default=None)
    out = [f"| {head} | before | after |", "|---|---|---|"]
    for label, before, after in rows:
        cell = _figure(before)
        out.append(f"| {label} | {f'**{cell}**' if before == largest else cell} | "
                   f"{_figure(after)} |")
    return out


def _clock(t_s: float) -> str:
    """A time on the recording's clock: 4 significant digits, as the other figures, below
    10,000 s; a later clock (another tool's Unix time, 1.7e9 s) in full to the hundredth,
    where 4 digits read '1.7e+09' for every block."""
    return f"{t_s:.4g}" if abs(t_s) < 1e4 else f"{t_s:.2f}"


def _localisation_lines(summary: dict) -> list[str]:
    """Where the residual was before and after the added effects: by direction of motion,
    speed, holds, time and each angle."""
    lb, la = summary["localisation_before"], summary["localisation_after"]
    lines = ["", "## Where the residual was", "",
             f"Held-out residual RMS in {summary['units']} before and after the added effects "
             f"(noise floor {summary['noise_floor']:.4g}); in bold the largest before.", "",
             "By the direction of each sensor's motion:", ""]
    lines += _before_after("direction", [(d, lb["by_direction"][d], la["by_direction"][d])
                                         for d in lb["by_direction"]])
    lines += ["", "By the speed of the movement (thirds of the moving frames):", ""]
    if lb["by_speed"]:
        lines += _before_after("speed (deg/s)", [
            (f"{b['lo_deg_s']:.4g} to {b['hi_deg_s']:.4g}", b["rms"], a["rms"])
            for b, a in zip(lb["by_speed"], la["by_speed"], strict=True)])
    else:
        lines.append("(too few moving frames to split)")
    hb, ha = lb["holds"], la["holds"]
    lines += ["", f"During the {hb['count']} holds of at least 1 s: {_figure(hb['rms'])} → "
              f"{_figure(ha['rms'])}; while moving: {_figure(hb.get('moving_rms'))} → "
              f"{_figure(ha.get('moving_rms'))}.", "", "By time:", ""]
    lines += _before_after("time (s)", [
        (f"{_clock(b['t0_s'])} to {_clock(b['t1_s'])}", b["rms"], a["rms"])
        for b, a in zip(lb["by_time"], la["by_time"], strict=True)])
    for name, cells in lb["by_angle"].items():
        lines += ["", f"By {name}:", ""]
        lines += _before_after(f"{name} (deg)", [
            (f"{b['lo_deg']:.4g} to {b['hi_deg']:.4g}", b["rms"], a["rms"])
            for b, a in zip(cells, la["by_angle"][name], strict=True)])
    return lines + _step_lines(lb["steps"], la["steps"], summary["units"], summary["angles"])


def _step_lines(before: list[dict], after: list[dict], units: str, angles: list[str]
                ) -> list[str]:
    """The sudden changes of the reading the simulation does not make (see
    :func:`~.localise.reading_steps`), after the added effects, with the count before."""
    counts = {e["sensor"]: e["count"] for e in before}
    lines = ["", "## Sudden changes of the reading", "",
             f"Where a sensor's reading, and its residual, moved by at least {STEP_SIGMAS:g} "
             f"noise SDs between the means of the {1000 * STEP_WINDOW_S:g} ms before and "
             f"after, from one level to another (by {STEP_FLATNESS:g} times the residual's "
             "spread within either), while the simulation moved by at most "
             f"{SIMULATED_SHARE:.0%} of that. None of the five effects makes a reading jump, "
             "so what the added effects leave of these stays in the gap. Steps that come back "
             f"at a pose (another step of the sensor within {SAME_POSE_DEG:g}° of it) at any "
             "speed say the reading is not a smooth function of the pose there: a tendon or a "
             "knit slipping over a bony prominence, a sensor catching on the fabric. Steps "
             "only while the joint moves fast are a response to the movement that none of the "
             "effects follows (on a joint that passes every pose each cycle they come back at "
             "a pose too). Steps at separate poses are knocks, or slips of the suit on the "
             "skin.", ""]
    if not after:
        return lines + [f"None after the added effects ({sum(counts.values())} before)."]
    lines += [f"| sensor | steps before | after | after, at a pose of another | median size "
              f"({units}) | median joint speed (deg/s) | largest: time (s), size, "
              f"{', '.join(angles)} (deg), speed (deg/s) |", "|---|---|---|---|---|---|---|"]
    for e in after:
        biggest = "; ".join(f"{_clock(x['t_s'])} s, {x['size']:+.4g}, "
                            + "/".join(f"{a:.4g}" for a in x["angles_deg"])
                            + f", {x['speed_deg_s']:.4g}" for x in e["largest"][:3])
        lines.append(f"| {e['sensor']} | {counts.get(e['sensor'], 0)} | {e['count']} | "
                     f"{e['at_a_recurring_pose']} | {e['median_size']:.4g} | "
                     f"{e['median_speed_deg_s']:.4g} | {biggest} |")
    return lines


#: Characters of a sensor name that Markdown reads as markup: a table's column bar,
#: emphasis, HTML, a link, code, the escape itself.
_MARKUP = str.maketrans({c: "\\" + c for c in "\\`*|<>[]"})


def _escaped_names(summary: dict) -> dict:
    """``summary`` with each sensor name that holds Markdown markup escaped wherever it stands
    alone (a list entry, a value, a key): the recording format takes any name without a
    comma or outer spaces, and 'F|x' would split a table row."""
    names = [*summary["sensors"], *(item["sensor"] for item in summary["sensors_ignored"])]
    escaped = {name: name.translate(_MARKUP) for name in names}
    escaped = {name: text for name, text in escaped.items() if text != name}
    if not escaped:
        return summary

    def walk(x: object) -> object:
        if isinstance(x, str):
            return escaped.get(x, x)
        if isinstance(x, dict):
            return {escaped.get(k, k): walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x

    return cast(dict, walk(summary))


def _invalid_causes(summary: dict) -> str:
    """The invalid frames by cause, the spikes per sensor (a summary written before the
    causes were kept: what an invalid frame may be)."""
    spikes = spike_counts(summary["sensors"], summary["spikes"])
    by_cause = summary.get("invalid_by_cause")
    if by_cause is None:
        return ("dropped, outside motion capture or in its dropouts, or holding an isolated "
                f"spike: {spikes}")
    why = invalid_words(by_cause)
    if by_cause.get("spike"):
        why += f": {spikes}"
    return why or "none"


def markdown(summary: dict) -> str:
    """The human-readable report."""
    summary = _escaped_names(summary)
    u = summary["units"]
    final = summary["static_map"]
    calibrated = summary.get("static_map_calibrated", final)
    lines = [f"# Discrepancy report: {summary['recording']}", "",
             f"Sensors: {', '.join(summary['sensors'])} ({u}); driven by "
             f"{', '.join(summary['angles'])} ({summary['joint']}), {summary['frames']} frames "
             f"at {summary['rate_hz']} Hz{_placed_words(summary)}, "
             f"{summary['invalid_frames']} invalid ({_invalid_causes(summary)})." + "".join(
                 f" Left out: {item['sensor']} {item['reason']}."
                 for item in summary["sensors_ignored"])
             + (f" {_sentence(resampled_words(summary['resampled_sensors']))}."
                if summary["resampled_sensors"] else "")
             + _filter_sentence(summary, u), "",
             f"**{summary['conclusion']}.** Held-out gap (sensor-space RMSE on "
             f"{summary['heldout_blocks']}-fold blocked cross-validation): "
             f"{summary['gap_before']:.4g} {u} before, {summary['gap_after']:.4g} {u} after; "
             f"noise floor {summary['noise_floor']:.4g} {u}.", "",
             *_clock_lines(summary, u),
             f"| step | effect | held-out gap ({u}) | removed RMS ({u}) | blocks improved |",
             "|---|---|---|---|---|",
             f"| 0 | calibrated static map ({map_words(calibrated)}) | "
             f"{summary['gap_before']:.4g} | | |"]
    for i, step in enumerate(summary["steps"], start=1):
        ev = step["evidence"]
        lines.append(f"| {i} | {step['effect']} | {step['gap']:.4g} | {ev['removed_rms']:.4g} "
                     f"| {ev['blocks_improved']}/{summary['heldout_blocks']} |")
    if map_words(final) != map_words(calibrated):
        lines += ["", f"With the effects in place the static map was chosen again: the final "
                      f"model's is {map_words(final)}."]
    kept = summary.get("drift_kept_heldout")
    if kept is not None and kept < DRIFT_KEPT_NOTED:
        lines += ["", f"{_sentence(drift_kept_words(kept))}."]
    for i, step in enumerate(summary["steps"], start=1):
        held = step["evidence"].get("held_at_stops")
        if held and held["significant"]:
            frames = held["frames_held"]
            lines += ["", f"Step {i} ({step['effect']}) on the sensors it holds at hard stops "
                      f"({', '.join(held['sensors'])}) alone: removed RMS "
                      f"{held['removed_rms']:.4g} {u} against their noise floor "
                      f"{held['noise_floor']:.4g} {u}; on the {frames['share']:.1%} of their "
                      f"frames it holds at the stops, {frames['removed_rms']:.4g} {u}."]
        alone = step["evidence"].get("on_one_sensor")
        if alone and alone["significant"]:
            lines += ["", f"Step {i} ({step['effect']}) on each sensor alone, every sensor's "
                      f"blocks against its own noise: " + "; ".join(
                          f"{name} removed RMS {r['removed_rms']:.4g} {u} against "
                          f"{r['noise_floor']:.4g} {u}, {_blocks(r['blocks_improved'])} improved"
                          for name, r in alone["sensors"].items()) + "."]
        low = step["evidence"].get("low_degrees")
        if low:
            beyond = low.get("beyond_noise_sensors")
            lines += ["", f"Step {i} ({step['effect']}) was counted on the drift it became: "
                      f"degrees 1–3 of time, which rank the candidates, removed RMS "
                      f"{low['removed_rms']:.4g} {u} against the noise floor "
                      f"{step['evidence']['noise_floor']:.4g} {u} and improved "
                      f"{_blocks(low['blocks_improved'])} (rule 2 needs {low['blocks_needed']})"
                      + (f"; beyond its own noise on {', '.join(beyond)} alone, on too few "
                         f"blocks there" if beyond else "") + ". " + _refined_count(
                             step["evidence"]["refined"], u)]
        rail = step["evidence"].get("pinned_at_rail")
        if rail:
            lines += ["", f"Step {i} ({step['effect']}) was named because "
                      f"{rail_words(rail, u)}, as a converter's floor or a range's limit holds "
                      f"it and no noise does: pinned at a rail. The stops left a held-out gap "
                      f"no larger than the model without them."]
        jumped = step["evidence"].get("jumped_in_hold")
        if jumped:
            lines += ["", f"Step {i} ({step['effect']}) was named because readings jumped "
                      f"while the joint held still, which no effect of the pose does (each "
                      f"jump's size in robust deviations of its sensor's level difference in "
                      f"holds): " + "; ".join(
                          f"{j['sensor']} by {j['height']:+.4g} {u} at {j['at_s']:.2f} s "
                          f"({j['robust_z']:.3g})" for j in jumped["jumps"])
                      + f". The drift it became lowered the held-out error beyond the noise "
                      f"on {', '.join(jumped['sensors'])}."]
    lines += _remainder_lines(summary)
    lines += _parameter_lines(summary)
    lines += _signature_lines(summary["steps"])
    if summary["not_added"]:
        lines += ["", "## Not added (not beyond the noise, not on enough blocks, or not "
                      "over whole movements)", "",
                  RULES_LEGEND, ""]
        for item in summary["not_added"]:
            ev = item["evidence"]
            curve = ev.get("against_smooth_curve")
            lines.append(f"- {item['effect']}: held-out gap {item['gap']:.4g}, removed RMS "
                         f"{ev['removed_rms']:.4g} vs noise floor {ev['noise_floor']:.4g}, "
                         f"{_blocks(ev['blocks_improved'])} improved (rule 2 needs "
                         f"{ev['blocks_needed']}): {_rules_failed(ev, u)}"
                         + ("" if curve is None else
                            f"; over a smooth transfer curve of each sensor (held-out gap "
                            f"{curve['curve_gap']:.4g}, the stops' {item['gap']:.4g}) the "
                            f"stops remove {curve['removed_rms']:.4g}, and the curve over "
                            f"them {curve['curve_over_stops']['removed_rms']:.4g}: a gentle "
                            f"bend, not a stop"))
    lines += _localisation_lines(summary)
    lines += ["", "![residual against time](residual_time.png)", "",
              "![residual against angle](residual_angle.png)", "", _profile_line(summary), ""]
    return "\n".join(lines)


#: What the rules of the "Not added" lines ask (rules.py; docs/discrepancy.md).
RULES_LEGEND = (
    "A candidate is named when, on held-out blocks, it removes more than the noise (rule 1: "
    "removed RMS above the noise floor), not on its best block alone and on enough blocks "
    "that chance would rarely do it (rule 2), and, for stops, bends more than a smooth curve "
    "of each sensor would (rule 3); judged over all sensors together and on each sensor "
    "alone (stops: on the frames they hold). Its gain must also hold over whole movements: "
    "averaged over half a second, the held-out error must be lower with it (rule 4; noise in "
    "the motion capture's angles changes from frame to frame).")


def _rules_failed(evidence: dict, units: str) -> str:
    """Which rules a candidate left unnamed fails over all sensors together
    (:func:`~.rules.rules_on_blocks`, :func:`~.rules.over_movements`): a drift counted on
    the drift it would become is judged on that count, a saturation that passes rules 1 and
    2 on its curve (rule 3); ``units``: the sensors'."""
    counted = evidence.get("refined")
    if counted is not None:
        failed = [] if counted["delta_mse"] > evidence["noise_floor"] ** 2 else [
            "removes less than the noise (rule 1)"]
        if counted["blocks_improved"] < counted["blocks_needed"]:
            failed.append(f"improves too few blocks (rule 2: {counted['blocks_improved']} of "
                          f"{counted['blocks_needed']} needed)")
        failed += _movements_failed(counted, units)
        head = (f"counted on the drift it would become (held-out gap "
                f"{counted['heldout_gap']:.4g}), it ")
    else:
        failed = []
        if evidence["delta_mse"] <= evidence["noise_floor"] ** 2:
            failed.append("removes less than the noise (rule 1)")
        if evidence["delta_mse_without_best_block"] <= 0:
            failed.append("rests on its best block (rule 2)")
        if evidence["blocks_improved"] < evidence["blocks_needed"]:
            failed.append("improves too few blocks (rule 2)")
        if not failed and evidence.get("against_smooth_curve") is not None:
            failed.append("bends no more than a smooth curve (rule 3)")
        failed += _movements_failed(evidence, units)
        head = "it "
    return head + ("; ".join(failed) if failed else
                   "falls short of rule 1 or 2 by less than the figures' precision")


def _movements_failed(evidence: dict, units: str) -> list[str]:
    """Rule 4's failure (:func:`~.rules.over_movements`) as a phrase of the "Not added"
    line, where the candidate lowers the held-out error at all; else nothing."""
    moved = evidence["over_movements"]
    if moved["holds"] or evidence["delta_mse"] <= 0:
        return []
    return [f"lowers the error only from frame to frame: averaged over {moved['window_s']:g} s "
            f"its mean square rises by {-moved['delta_mse']:.3g} {units}² (rule 4)"]


def _profile_line(summary: dict) -> str:
    """How to use ``suit_profile.toml``: in ``exohil simulate`` where the suit is driven by
    shoulder angles, in Python for any joint; a model that leaves more than the noise is the
    best fit found, and the line says so."""
    line = "The updated model is `suit_profile.toml` (schema exohil-calibrated-suit-profile): "
    if all(name in ANGLE_NAMES for name in summary["angles"]):
        line += ("`exohil simulate --profile suit_profile.toml --out sim.mcap` runs it on any "
                 "shoulder movement; in Python, ")
    else:
        line += (f"it is driven by {', '.join(summary['angles'])} ({summary['joint']}), not "
                 "by shoulder angles, so `exohil simulate` cannot run it; in Python, "
                 "`simulate_calibrated(suit, t, angles_deg)` simulates it and ")
    line += "`exohil.emulators.discrepancy.load_calibrated_profile` reads it."
    left = summary["remainder"]
    if left["beyond_noise"]:
        line += (f" It leaves {left['gap_over_floor']:.3g}× the noise floor (\"What remains\"): "
                 "it is the best fit found, not a faithful model of the suit.")
    return line


def write_outputs(outcome: Outcome, out_dir: Path, profile_name: str,
                  workers: int | None = None) -> list[Path]:
    """Write every output into ``out_dir`` (created if needed); returns the paths. All of
    them are written under temporary names before any is renamed into place (module doc):
    an exception or Ctrl-C before the renames leaves ``out_dir``'s earlier files as they
    were. The plots are drawn in up to ``workers`` processes (default: one per CPU, one
    inside a worker process; :func:`~.workers.workers_for`)."""
    files: dict[str, bytes] = plots(outcome, workers)
    suit = calibrated_suit(outcome, profile_name)
    files["suit_profile.toml"] = to_toml(profile_dict(
        suit, f"calibrated by exohil discrepancy from {outcome.summary['recording']}")
    ).encode("utf-8")
    files["report.md"] = markdown(outcome.summary).encode("utf-8")
    # allow_nan=False: NaN is not JSON; a statistic with no frame to measure is null
    summary = json.dumps(outcome.summary, indent=1, allow_nan=False)
    files["discrepancy.json"] = (summary + "\n").encode("utf-8")
    out_dir.mkdir(parents=True, exist_ok=True)  # once the plots are drawn: nothing before
    written = [out_dir / name for name in OUTPUT_NAMES]
    staged: list[Path] = []
    try:
        for path in written:  # each complete under its temporary name first
            staged.append(temporary_name(path))
            write_bytes(staged[-1], files[path.name])
        for tmp, path in zip(staged, written, strict=True):
            os.replace(tmp, path)
    finally:
        for tmp in staged:
            tmp.unlink(missing_ok=True)
    return written
