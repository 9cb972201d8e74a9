"""The device's frame rate as its own frames show it, against the configured one.

The configured rate (``--rate``, the bench's, the reference's, else 250 Hz) is what the run
assumes; the device's sequence numbers and device timestamps say what it actually does: the
measured rate is (last seq − first seq) / (last device time − first device time) over the
frames received, so frames lost on the way (sequence gaps) do not lower it, while a device that
samples slower than configured (e.g. firmware held back by a blocking call) does.
"""

from __future__ import annotations

#: Relative difference between measured and configured rate beyond which a run warns.
DEVICE_RATE_TOLERANCE = 0.01
#: Device time the frames must span before their rate is trusted, s.
MIN_SPAN_S = 1.0


def measured_rate_hz(first_seq: int | None, last_seq: int | None, first_time_s: float,
                     last_time_s: float, missed_in_resets: int = 0) -> float | None:
    """Frames per second of device time between two frames, or None when they span less
    than :data:`MIN_SPAN_S` (or there are none).

    ``missed_in_resets`` (the link's ``dropped_in_resets``) adds the frames a device reboot
    missed: across a restarted numbering the host's sequence goes on by one while its device
    time goes on by the gap, so without them a reboot would lower the rate."""
    if first_seq is None or last_seq is None:
        return None
    span_s = last_time_s - first_time_s
    if not span_s >= MIN_SPAN_S or last_seq <= first_seq:
        return None
    return (last_seq + missed_in_resets - first_seq) / span_s


def device_rate_warning(measured_hz: float | None, configured_hz: float) -> str | None:
    """Why the device's measured rate does not match the configured one, or None."""
    if measured_hz is None or abs(measured_hz - configured_hz) <= (
            DEVICE_RATE_TOLERANCE * configured_hz):
        return None
    return (f"the device sends {measured_hz:.1f} frames/s by its own timestamps, not the "
            f"configured {configured_hz:g} Hz (more than {DEVICE_RATE_TOLERANCE:.0%} apart): "
            "check the firmware's loop, or give the device's rate with --rate")
