"""Markdown tables of a model comparison in the layout of Varghese et al., Table I
(one row per method, one RMSE column per estimated angle, degrees), plus a detail table.

:func:`write_section` replaces (or appends) a named section of a Markdown file between
``<!-- table:NAME -->`` and ``<!-- /table:NAME -->`` markers, so several generated tables and
hand-written text can live in one ``docs/results.md``.
"""

from __future__ import annotations

import math
from pathlib import Path

from exohil.estimator.coverage import OUTSIDE_SHARE_PERCENT
from exohil.estimator.workflow import ModelResult
from exohil.formats.atomic import write_text
from exohil.formats.errors import InputError

METHOD_NAMES = {
    "ann": "ANN (memoryless MLP, Varghese 2019 baseline)",
    "cnn": "CNN (1-D temporal conv, after Ogata 2019)",
    "classical": "Classical (PI play operators + creep + quadratic, ridge)",
    "lnnet": "LNNet (late fusion LSTM)",
    "ennet": "ENNet (early fusion LSTM over a window, as in the paper)",
    "ennet-stateful": "ENNet, stateful (LSTM state carried frame to frame)",
}


def comparison_markdown(
    results: list[ModelResult], angles: tuple[str, ...], *, title: str, command: str,
    split: str, data: str,
) -> str:
    """The Table-I-style RMSE table in exohil's accuracy definition (RMSE per angle where the
    elevation is at least 20°, plus the arm-direction RMSE over all frames, for a shoulder
    model), a detail table (all-frames RMSE, MAE, max, the test frames outside the readings
    each model was trained on, training) and provenance."""
    shoulder = any("accuracy.direction_rmse" in r.test.get("accuracy", {}) for r in results)
    where = " where φ ≥ 20°" if shoulder else ""
    head = ("| Method | " + " | ".join(f"{a} RMSE{where} (°)" for a in angles)
            + (" | arm direction RMSE, all frames (°) |" if shoulder else " |"))
    lines = [f"### {title}", "", f"Data: {data}", "", f"Split: {split}", "", head,
             "|---|" + "---:|" * (len(angles) + shoulder)]
    for r in results:
        acc = r.test.get("accuracy", {})
        cells = [_deg(acc.get(f"accuracy.rmse.{a}")) for a in angles]
        if shoulder:
            cells.append(_deg(acc.get("accuracy.direction_rmse")))
        lines.append(f"| {METHOD_NAMES.get(r.kind, r.kind)} | {' | '.join(cells)} |")
    lines += ["", "| Method | " + " | ".join(f"{a} RMSE / MAE / max, all frames (°)"
                                            for a in angles)
              + " | test frames outside training (%) | window | epochs (best) | stopped by "
              "| train s |",
              "|---|" + "---:|" * (len(angles) + 5)]
    for r in results:
        info = r.estimator.info
        detail = " | ".join(f"{r.test['rmse'][a]:.2f} / {r.test['mae'][a]:.2f} / "
                            f"{r.test['max'][a]:.1f}" for a in angles)
        cfg = r.estimator.config
        window = ("carried state" if cfg.stateful else "—" if cfg.window in (None, 1)
                  else f"{cfg.window}×{cfg.dilation}")
        epochs = f"{info.get('epochs', '—')} ({info.get('best_epoch', '—')})"
        lines.append(f"| {r.kind} | {detail} | {_outside(r)} | {window} | {epochs} | "
                     f"{info.get('stopped_by', 'closed form')} | {info.get('train_seconds')} |")
    lines += ["", f"Test frames: {results[0].test['frames'] if results else 0}."]
    if any(_deg(r.test.get("accuracy", {}).get(f"accuracy.rmse.{a}")) == "—"
           for r in results for a in angles):
        lines += ["", "—: not measured (no test frame reached 20° of elevation)."]
    told = [r.kind for r in results if r.coverage.warns]
    if told:
        lines += ["", f"**{', '.join(told)}: {OUTSIDE_SHARE_PERCENT:g} % or more of the test "
                  "frames lie outside the readings the model was trained on** (another suit "
                  "or donning, or movements only the test part holds): its figures there "
                  "measure extrapolation (docs/estimator.md)."]
    lines += ["", "Made by:", "", "```", command, "```"]
    return "\n".join(lines) + "\n"


def _outside(result: ModelResult) -> str:
    share = result.coverage.outside_percent
    return "—" if share is None else f"{share:.2f}"


def _deg(value: float | None) -> str:
    """Degrees to two places; "—" for a figure not measured (None, or NaN: no frame)."""
    return "—" if value is None or not math.isfinite(value) else f"{value:.2f}"


def _markers(name: str) -> tuple[str, str]:
    return f"<!-- table:{name} -->", f"<!-- /table:{name} -->"


def check_section(path: Path, name: str) -> None:
    """Refuse (:class:`InputError`) a ``path`` whose markers of section ``name`` do not make
    one section: :func:`write_section` would replace text outside it. Absent file: fine."""
    if path.exists():
        _check_markers(path, path.read_text(encoding="utf-8"), name)


def _check_markers(path: Path, text: str, name: str) -> None:
    start, end = _markers(name)
    opened, closed = text.count(start), text.count(end)
    if (opened, closed) in ((0, 0), (1, 1)) and (opened == 0 or text.index(start) <
                                                 text.index(end)):
        return
    raise InputError(f"{path}: the markers of section {name!r} do not make one section "
                     f"({opened} × '{start}', {closed} × '{end}', in that order or not); "
                     "mend them by hand or choose another --section, so that no text of "
                     "yours is replaced")


def write_section(path: Path, name: str, text: str) -> None:
    """Put ``text`` between the section markers of ``name`` in ``path`` (created if absent);
    every other byte of the file stays. Markers that do not pair up are refused
    (:func:`check_section`)."""
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    _check_markers(path, old, name)
    start, end = _markers(name)
    block = f"{start}\n{text}{end}"
    if start in old:
        head, _, rest = old.partition(start)
        new = head + block + rest.partition(end)[2]
    else:
        new = (old.rstrip("\n") + "\n\n" if old else "") + block + "\n"
    write_text(path, new)
