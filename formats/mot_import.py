"""OpenSim shoulder kinematics (``.mot``) → a mocap-only recording.

MoBL-ARMS / thoracoscapular coordinate names map to recording angle fields:
``plane_elv`` → ``elv_angle``, ``shoulder_elv`` → ``shoulder_elv``, ``axial_rot`` →
``shoulder_rot`` (degrees; radians files are converted). The result has no sensors
(``sensor_names == ()``, an empty sensor stream, no ``/suit/sensors`` channel when written).
"""

from __future__ import annotations

import numpy as np

from exohil.formats.errors import RecordingError
from exohil.formats.opensim_mot import MotData
from exohil.formats.recording import AngleStream, Recording, SensorStream

MOT_TO_SHOULDER = {
    "plane_elv": "elv_angle",
    "shoulder_elv": "shoulder_elv",
    "axial_rot": "shoulder_rot",
}
SINGLE_SAMPLE_RATE_HZ = 100.0


def shoulder_recording_from_mot(mot: MotData, metadata: dict[str, str]) -> Recording:
    """A recording whose only stream is ``/mocap/shoulder`` from the ``.mot`` coordinates.

    Times are the file's ``time`` column (seconds); the nominal mocap rate is the file's mean
    rate rounded to 1e-3 Hz (``SINGLE_SAMPLE_RATE_HZ`` for a one-row file).
    Raises RecordingError when a needed coordinate is missing.
    """
    missing = [name for name in MOT_TO_SHOULDER if name not in mot.columns]
    if missing:
        raise RecordingError(f".mot data lacks shoulder coordinate(s) {missing}")
    angles = np.column_stack([mot.columns[name] for name in MOT_TO_SHOULDER])
    if not mot.in_degrees:
        angles = np.degrees(angles)
    rate = mot.rate_hz
    return Recording(
        sensor_names=(),
        sensors=SensorStream(
            seq=np.empty(0, dtype=np.int64), t=np.empty(0), values=np.empty((0, 0))
        ),
        mocap={"shoulder": AngleStream(mot.time.copy(), tuple(MOT_TO_SHOULDER.values()), angles)},
        mocap_rate_hz=round(rate, 3) if np.isfinite(rate) else SINGLE_SAMPLE_RATE_HZ,
        metadata=metadata,
    )
