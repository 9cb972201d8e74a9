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
from exohil.formats.recording_messages import first_non_finite

MOT_TO_SHOULDER = {
    "plane_elv": "elv_angle",
    "shoulder_elv": "shoulder_elv",
    "axial_rot": "shoulder_rot",
}


def shoulder_recording_from_mot(mot: MotData, metadata: dict[str, str]) -> Recording:
    """A recording whose only stream is ``/mocap/shoulder`` from the ``.mot`` coordinates.

    Times are the file's ``time`` column (seconds); the nominal mocap rate is the file's mean
    rate rounded to 1e-3 Hz. Raises RecordingError, naming the row and column, when a needed
    coordinate is missing or not a finite number, a time is negative (a recording's times
    start at 0 or later) or there are fewer than two rows.
    """
    missing = [name for name in MOT_TO_SHOULDER if name not in mot.columns]
    if missing:
        raise RecordingError(f".mot data lacks shoulder coordinate(s) {missing}")
    angles = np.column_stack([mot.columns[name] for name in MOT_TO_SHOULDER])
    bad = first_non_finite(angles)
    if bad is not None:
        row, col = bad
        raise RecordingError(f"data row {row + 1}, column {list(MOT_TO_SHOULDER)[col]}: "
                             f"{angles[row, col]} is not a finite number")
    if len(mot.time) and mot.time[0] < 0:
        raise RecordingError(f"data row 1: time {mot.time[0]:g} s; a recording's times start "
                             "at 0 or later")
    rate = mot.rate_hz
    if not np.isfinite(rate):
        raise RecordingError(f"{len(mot.time)} data row(s): a motion needs at least two")
    if not mot.in_degrees:
        angles = np.degrees(angles)
    return Recording(
        sensor_names=(),
        sensors=SensorStream(
            seq=np.empty(0, dtype=np.int64), t=np.empty(0), values=np.empty((0, 0))
        ),
        mocap={"shoulder": AngleStream(mot.time.copy(), tuple(MOT_TO_SHOULDER.values()), angles)},
        mocap_rate_hz=round(rate, 3),
        metadata=metadata,
    )
