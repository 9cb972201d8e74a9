"""Simulate a suit recording: trajectory → tendon geometry → effect chain → :class:`Recording`.

The sensor stream runs at 250 Hz on the device clock (frame k at k / 250 s, plus any clock
offset a lag effect adds); its sequence numbers are the frame indices, so dropped frames leave
gaps. Motion capture (``/mocap/shoulder``: elv_angle, shoulder_elv, shoulder_rot in degrees)
runs at 120 Hz on the trajectory's clock and is exact (ground truth).
"""

from __future__ import annotations

import numpy as np

from exohil import __version__
from exohil.emulators.effects import EffectChain, Signal
from exohil.emulators.protocols import ANGLE_NAMES, MOCAP_RATE_HZ, Trajectory
from exohil.emulators.suit_profile import SuitProfile
from exohil.formats.recording import AngleStream, Recording, SensorStream

SENSOR_RATE_HZ = 250.0
MOCAP_JOINT = "shoulder"


def geometric_signal(trajectory: Trajectory, profile: SuitProfile,
                     rate_hz: float = SENSOR_RATE_HZ) -> Signal:
    """Ideal tendon path lengths (mm) at ``rate_hz`` along the trajectory, before any effect."""
    t = trajectory.frame_times(rate_hz)
    angles = np.deg2rad(trajectory.sample(t))
    lengths = profile.geometry.path_lengths(angles[:, 0], angles[:, 1], angles[:, 2])
    return Signal.from_values(t, lengths)


def simulate(trajectory: Trajectory, profile: SuitProfile, seed: int,
             effects: EffectChain | None = None) -> Recording:
    """A recording of the simulated suit following ``trajectory``.

    ``effects`` replaces the profile's effect chain when given (``EffectChain([])`` gives the
    ideal geometric lengths). Deterministic for a given (trajectory, profile, seed, effects).
    """
    chain = profile.effects if effects is None else effects
    signal = chain.apply(geometric_signal(trajectory, profile), seed=int(seed))
    frames = np.arange(signal.t.shape[0], dtype=np.int64)
    sensors = SensorStream(seq=frames[signal.keep], t=signal.t[signal.keep],
                           values=signal.values[signal.keep])
    t_mocap = trajectory.frame_times(MOCAP_RATE_HZ)
    mocap = AngleStream(t=t_mocap, names=ANGLE_NAMES, angles=trajectory.sample(t_mocap))
    metadata = {
        "generator": f"exohil.emulators.simulate {__version__}",
        "seed": str(int(seed)),
        "trajectory": trajectory.source,
        "suit_profile": profile.name,
        "suit_profile_sha256": profile.sha256(),
        "effect_chain": chain.to_json(),
    }
    return Recording(sensor_names=profile.sensor_names, sensors=sensors,
                     mocap={MOCAP_JOINT: mocap}, sensor_units="mm",
                     sensor_rate_hz=SENSOR_RATE_HZ, mocap_rate_hz=MOCAP_RATE_HZ,
                     segments=list(trajectory.segments), metadata=metadata)
