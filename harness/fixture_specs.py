"""The committed simulated recordings under ``fixtures/``: what each one is and how it is made.

Every fixture is a pure function of committed inputs (the default suit profile, a fixed seed
and, for real motion, the shoulder-ik trials), written with the deterministic recording writer,
so a rebuild on the same platform is bit-identical. ``exohil fixtures build`` regenerates them;
``--check`` compares a rebuild against ``fixtures/SHA256SUMS``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from exohil.emulators.protocols import Trajectory, mot_trajectory, paper_protocol
from exohil.emulators.simulate import simulate
from exohil.emulators.suit_profile import load_default_profile
from exohil.formats.recording_writer import write_recording

PAPER_SEED = 20201
REAL_MOTION_SEED = 20202
#: The held-out recording: same suit and protocol, another draw of the movement and the noise.
#: The reference models never saw it (they train on paper_protocol.mcap), so the demo and the
#: conformance suite score them on it.
HELDOUT_SEED = 20203
#: shoulder-ik trials (OpenSim IK, 100 Hz, CC BY 4.0) concatenated for the real-motion fixture.
REAL_MOTION_TRIALS = ("ABD01.mot", "FLX01.mot", "ABD21.mot", "FLX21.mot")
#: files copied verbatim from the shoulder-ik folder next to the fixtures derived from it
SHOULDER_IK_NOTICES = {"LICENSE_data": "LICENSE_shoulder-ik_data",
                       "SOURCE.md": "SOURCE_shoulder-ik.md"}
#: the ``license`` metadata of a fixture derived from them (docs/recording-format.md)
SHOULDER_IK_LICENSE = ("CC BY 4.0, Seth et al. thoracoscapular data, IK by Belli et al. "
                       "(rmr-solver)")
SUMS_FILE = "SHA256SUMS"


@dataclass(frozen=True)
class FixtureSpec:
    """One fixture file.

    Attributes:
        filename: file name inside the fixtures folder.
        description: provenance in one line.
        seed: simulation seed.
        trajectory: builds the movement from the shoulder-ik folder (ignored when not needed).
        needs_shoulder_ik: whether the real shoulder-ik data are required.
    """

    filename: str
    description: str
    seed: int
    trajectory: Callable[[Path], Trajectory]
    needs_shoulder_ik: bool


FIXTURES: tuple[FixtureSpec, ...] = (
    FixtureSpec(
        filename="paper_protocol.mcap",
        description=(f"Table III protocol (paper_protocol seed {PAPER_SEED}), default suit "
                     f"profile with every effect on, simulation seed {PAPER_SEED}"),
        seed=PAPER_SEED,
        trajectory=lambda _ik: paper_protocol(PAPER_SEED),
        needs_shoulder_ik=False,
    ),
    FixtureSpec(
        filename="paper_protocol_heldout.mcap",
        description=(f"held-out: Table III protocol (paper_protocol seed {HELDOUT_SEED}), default "
                     f"suit profile with every effect on, simulation seed {HELDOUT_SEED}; never "
                     "used to train the reference models"),
        seed=HELDOUT_SEED,
        trajectory=lambda _ik: paper_protocol(HELDOUT_SEED),
        needs_shoulder_ik=False,
    ),
    FixtureSpec(
        filename="real_motion_abd_flx.mcap",
        description=("real shoulder motion from shoulder-ik " + ", ".join(REAL_MOTION_TRIALS)
                     + f" (1 s bridges), default suit profile, every effect on, "
                       f"simulation seed {REAL_MOTION_SEED}"),
        seed=REAL_MOTION_SEED,
        trajectory=lambda ik: mot_trajectory([ik / name for name in REAL_MOTION_TRIALS]),
        needs_shoulder_ik=True,
    ),
)


def build_fixture(spec: FixtureSpec, out_dir: Path, shoulder_ik_dir: Path) -> Path:
    """Simulate one fixture and write it into ``out_dir``; returns its path."""
    if spec.needs_shoulder_ik and not shoulder_ik_dir.is_dir():
        raise FileNotFoundError(f"{spec.filename} needs the shoulder-ik data at {shoulder_ik_dir}")
    recording = simulate(spec.trajectory(shoulder_ik_dir), load_default_profile(), spec.seed)
    if spec.needs_shoulder_ik:  # the data's terms go with what derives from it (as on import)
        recording.metadata["license"] = SHOULDER_IK_LICENSE
        recording.metadata.update({f"notice.{name}": (shoulder_ik_dir / name).read_text("utf-8")
                                   for name in SHOULDER_IK_NOTICES})
    path = out_dir / spec.filename
    write_recording(path, recording)
    return path


def format_sums(hashes: dict[str, str]) -> str:
    """``sha256sum``-compatible text: one ``<hex>  <filename>`` line per file, sorted."""
    return "".join(f"{digest}  {name}\n" for name, digest in sorted(hashes.items()))


def parse_sums(text: str) -> dict[str, str]:
    """Inverse of :func:`format_sums`; raises ValueError on a malformed line."""
    out = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        digest, sep, name = line.partition("  ")
        if not sep or len(digest) != 64 or not name:
            raise ValueError(f"{SUMS_FILE} line {number} is not '<sha256>  <file>': {line!r}")
        out[name] = digest
    return out
