"""A recording as the discrepancy workflow sees it: sensors and angles on one uniform grid.

The grid is the device's frame counter: frame ``seq`` sits at index ``seq − seq₀``, so dropped
frames (sequence gaps) are grid points marked invalid instead of a silently shorter series;
where the frames' times disagree with the counter about a gap, the times place it
(:func:`frame_grid`).
Their times are interpolated from the neighbouring frames; the mocap angles, made continuous
across wraps and low-passed (:func:`smooth_angles`), are interpolated at every grid time.
Filters and history-dependent effects then run on a uniform clock.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import butter, sosfiltfilt

from exohil.formats.alignment import MOCAP_GAP_INTERVALS, in_mocap_gap, mocap_step
from exohil.formats.errors import InputError
from exohil.formats.recording import AngleStream, Recording

#: Folds of the blocked cross-validation.
N_BLOCKS = 8
#: Length of one held-out contiguous block, s (about one movement or hold).
BLOCK_S = 2.5
#: Shortest usable recording, s: every fold must hold out at least one block.
MIN_BLOCK_S = BLOCK_S
#: Invalid runs longer than this, s, do not count towards a held-out block's length
#: (:func:`held_out_blocks`): a dropout, not frames lost here and there.
SKIPPED_RUN_S = 0.1
#: The motion capture's angles may be low-passed at these cutoffs, Hz, each tried in turn,
#: the next only where the one before it predicted the held-out readings better, with a
#: Butterworth filter of order ``MOCAP_FILTER_ORDER`` run forward and back (zero phase: no
#: lag is added to the pose). Arm movement holds little above 5 Hz, where the filter at
#: 12 Hz passes 99.9 % of the amplitude (at 6 Hz 81 %, and 99.6 % at 3 Hz: hence the rules
#: a lower cutoff must clear). Above the cutoff a tracker's white noise may be all there
#: is, which the static map would read as sensor motion the suit never made (0.3° of it on
#: a clean suit was named hysteresis: the play operator smoothed it away; 0.5° on two of
#: three suits still was at 12 Hz, and nothing was at 6 Hz). The workflow chooses (see
#: :func:`exohil.emulators.discrepancy.timing.mocap_filter`).
MOCAP_CUTOFFS_HZ = (12.0, 6.0)
MOCAP_FILTER_ORDER = 4
#: Motion capture sampled so slowly that the cutoff is above this share of its Nyquist
#: frequency is used as it is (the filter would remove next to nothing).
MOCAP_FILTER_MAX_NYQUIST = 0.8
#: A sensor frame grid may hold at most this many points per frame received (90 % dropped).
MAX_GRID_PER_FRAME = 10
#: The frame period is measured over spans of this many frames (:func:`frame_grid`).
PERIOD_SPAN = 64
#: A gap between frames that the counter and the frames' times put this far apart, s, or
#: further, is placed by the times; each side's clock offset is its median over
#: ``JUMP_WINDOW_S`` of frames next to the gap.
JUMP_DISAGREE_S = 0.5
JUMP_WINDOW_S = 1.0
#: Frame times of which this share or more, between consecutive frames, are closer than a
#: quarter of the frame period were stamped by a host as the frames arrived in bursts:
#: the grid takes steady times instead (:func:`grid_times`).
BUNCHED_SHARE = 0.1
#: ``Trial.placed_by`` when seq is a plain frame counter (one per frame).
FRAME_COUNTER = "frame counter"
#: A sensor with readings on fewer frames than this share is left out of the analysis.
MIN_SENSOR_COVERAGE = 0.5
#: An isolated spike is a reading further than ``SPIKE_SIGMAS`` noise standard deviations
#: from the median of the ``SPIKE_WINDOW`` frames centred on it (a run of at most two
#: frames: a step, a loop or a fast move keeps its median) ...
SPIKE_WINDOW = 5
SPIKE_SIGMAS = 10.0
#: ... the noise measured over the ``SPIKE_NOISE_WINDOW`` frames around it where that is
#: larger than the sensor's floor (a resistive sensor is noisier at high strain).
SPIKE_NOISE_WINDOW = 51
#: White-noise σ from the robust spread of second differences: var Δ²y = 6σ² for white
#: noise, and 1.4826 × MAD is σ for a normal distribution.
D2_MAD_TO_SIGMA = 1.4826 / math.sqrt(6.0)
#: Readings whose step is coarser than this share of their noise are measured by a clipped
#: standard deviation instead: a median of quantised differences moves in half-steps, up to
#: about 0.3·q/σ of it, 10 % at this share (an ADC count read with 0.86 counts of noise
#: gave a MAD floor of 0.61 counts). Finer steps keep the MAD, which ignores the movement's
#: share of the differences better.
QUANTISED_SHARE = 0.3
#: Second differences further than this many standard deviations from their median are left
#: out of the clipped estimate (movement onsets, glitches); ``D2_CLIP_VARIANCE`` is the share
#: of a normal variable's variance kept inside ±``D2_CLIP_SIGMAS``, divided out.
D2_CLIP_SIGMAS = 4.0
D2_CLIP_VARIANCE = 1.0 - 2.0 * D2_CLIP_SIGMAS * math.exp(-D2_CLIP_SIGMAS ** 2 / 2.0) / (
    math.sqrt(2.0 * math.pi) * math.erf(D2_CLIP_SIGMAS / math.sqrt(2.0)))
#: Second differences over k frames spread like those over one for white noise, and at most
#: k² times as wide for a movement whose noise vanishes (a smooth reading's Δ² grows with
#: the square of its span). Readings whose second differences over some span k of 2 to
#: ``RESAMPLED_STRIDES`` frames spread wider than k² noise floors change less from one frame
#: to the next than noise or movement can make them: a stream resampled from a slower
#: sensor (each reading interpolated, or held over several frames), whose frame-to-frame
#: floor is far too low (:func:`resampled_spread`). Its floor is then the widest of those
#: spreads (:func:`noise_floor`): once their span reaches the slower sensor's sample spacing
#: they see its own noise (held readings all of it, interpolated ones about 0.8).
RESAMPLED_STRIDES = 8
#: ``resampled_spread`` over this is such a stream.
RESAMPLED_SPREAD = 1.0
#: The noise floor is measured on runs of three frames received in a row; with fewer than
#: ``MIN_NOISE_TRIPLES`` of them (frames seldom arrive three in a row: a link that drops
#: three of every five) triples of successive received frames that span at most
#: ``MAX_NOISE_SPAN`` frame times count too, and fewer than ``NOISE_TRIPLES_NEEDED`` in all
#: is an error.
MIN_NOISE_TRIPLES = 500
MAX_NOISE_SPAN = 6
NOISE_TRIPLES_NEEDED = 50


class DiscrepancyError(InputError, ValueError):
    """A recording the workflow cannot use; the message is one line saying why."""


@dataclass
class Trial:
    """Sensors and angles on a uniform frame grid.

    Attributes:
        t: (N,) s, grid times on the sensor clock.
        y: (N, S) sensor values in ``units`` (interpolated across dropped frames).
        valid: (N,) bool; False for dropped frames and frames outside the mocap span or in
            one of its dropouts (:func:`in_mocap_gap`).
        angles: (N, A) degrees, the joint's moving angles at the grid times.
        angle_names: names of the angle columns.
        joint: mocap joint (topic suffix).
        sensor_names: names of the sensor columns.
        units: sensor unit (e.g. "mm").
        rate_hz: grid rate, Hz.
        blocks: (N,) int, the fold (0 … N_BLOCKS − 1) that holds each frame out.
        noise: (S,) white-noise standard deviation per sensor (:func:`noise_floor`).
        scored: (N,) bool, valid frames whose held-out residual counts in the gap (see
            :func:`exohil.emulators.discrepancy.model.restrict_to_coverage`).
        ignored: sensors of the recording left out of the analysis, each with the reason
            (:func:`unusable_sensors`); ``sensor_names`` lists only the analysed ones.
        spikes: (S,) int, frames per sensor holding an isolated spike (:func:`spikes`),
            which are invalid.
        invalid_by_cause: the invalid frames by their first cause, in this order:
            ``dropped`` (no sensor frame there), ``outside_motion_capture`` (before or after
            its span, or in one of its dropouts), ``not_finite`` (a reading NaN or
            infinite), ``spike`` (an isolated spike on some sensor); the counts add up to
            the invalid frames.
        resampled: (S,) the widest spread of the readings' second differences over k = 2 …
            ``RESAMPLED_STRIDES`` frames, each over k² noise floors (:func:`resampled_spread`);
            over ``RESAMPLED_SPREAD``, a stream resampled from a slower sensor, whose floor is
            measured over several frames (:func:`noise_floor`).
        placed_by: how frames were put on the grid (:func:`frame_grid`), for the messages.
        time_scatter_s: how far the recorded frame times scatter about a steady rate, s RMS.
        times_steady: whether ``t`` is that steady rate's times, the recorded ones having
            been stamped on arrival (:func:`grid_times`).
        mocap_late_s: s, how much later than the sensors' clock the motion capture stamps
            its samples (a clock offset); ``angles`` are read that much later.
        mocap_skew: s per s, how much faster the motion capture's clock runs than the
            sensors' (a clock rate difference): ``angles`` at grid time t are read a further
            ``mocap_skew`` · (t − the grid's first time) late.
        mocap_low_pass_hz: the cutoff the motion capture's angles were low-passed at
            (:func:`smooth_angles`), Hz; None: read as sampled.
        cache: what the fits derive from this trial (its fit rows, from ``valid`` and
            ``blocks``; the average of the last shared design block; the joint's motion
            and the frames it moves fast). Not an argument: a copy made with
            ``dataclasses.replace`` starts with an empty one.
    """

    t: np.ndarray
    y: np.ndarray
    valid: np.ndarray
    angles: np.ndarray
    angle_names: tuple[str, ...]
    joint: str
    sensor_names: tuple[str, ...]
    units: str
    rate_hz: float
    blocks: np.ndarray
    scored: np.ndarray
    noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ignored: tuple[tuple[str, str], ...] = ()
    spikes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    invalid_by_cause: dict[str, int] = field(default_factory=dict)
    resampled: np.ndarray = field(default_factory=lambda: np.zeros(0))
    placed_by: str = FRAME_COUNTER
    time_scatter_s: float = 0.0
    times_steady: bool = False
    mocap_late_s: float = 0.0
    mocap_low_pass_hz: float | None = None
    mocap_skew: float = 0.0
    cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    @property
    def n_sensors(self) -> int:
        return int(self.y.shape[1])


def _joint(rec: Recording) -> str:
    """The shoulder when recorded, else the joint with the most samples."""
    if "shoulder" in rec.mocap and len(rec.mocap["shoulder"]) > 1:
        return "shoulder"
    return max(rec.mocap, key=lambda name: len(rec.mocap[name]))


def mocap_samples(stream: AngleStream) -> tuple[np.ndarray, np.ndarray]:
    """A joint's tracked samples in time order: times (M,) s and angles (M, A) degrees made
    continuous across wraps (:func:`continuous_angles`). Samples with a NaN angle (markers
    lost) or time are left out."""
    order = np.argsort(stream.t, kind="stable")
    t_mocap = np.asarray(stream.t, dtype=np.float64)[order]
    raw = np.asarray(stream.angles, dtype=np.float64)[order]
    tracked = np.all(np.isfinite(raw), axis=1) & np.isfinite(t_mocap)
    kept = raw[tracked]
    return t_mocap[tracked], (continuous_angles(kept) if len(kept) else kept)


def prepare_trial(rec: Recording, name: str = "recording", mocap_late_s: float = 0.0,
                  mocap_low_pass_hz: float | None = None, mocap_skew: float = 0.0) -> Trial:
    """Put a recording on its uniform frame grid and split it into held-out blocks.

    ``mocap_late_s``: a clock offset, s: the pose at sensor time t is the mocap's at
    t + ``mocap_late_s`` + ``mocap_skew`` · (t − t₀), t₀ the first time of the sensors'
    grid (``mocap_skew``: a clock rate difference, s per s). ``mocap_low_pass_hz``:
    low-pass the mocap's angles at this cutoff (:func:`smooth_angles`); None: as sampled.
    Either way they are made continuous across wraps (:func:`continuous_angles`).

    Sensors without usable readings (:func:`unusable_sensors`) are left out and listed in
    ``Trial.ignored``: one dead channel should not hide what the others show.

    Raises:
        DiscrepancyError: no sensors, no usable sensor, no motion capture (or no two finite
            mocap samples), no moving angle, most sensor frames missing
            (``MAX_GRID_PER_FRAME``), or too short for ``N_BLOCKS`` blocks of at least
            ``MIN_BLOCK_S`` seconds.
    """
    if len(rec.sensors) < 2 or not rec.sensor_names:
        raise DiscrepancyError(f"{name}: no sensor frames; the workflow needs sensors and "
                               "motion capture")
    if not rec.mocap or all(len(s) < 2 for s in rec.mocap.values()):
        raise DiscrepancyError(f"{name}: no motion capture; the workflow simulates the sensors "
                               "from the measured angles, so it needs a /mocap/<joint> stream")
    joint = _joint(rec)
    stream = rec.mocap[joint]
    t_frames = np.asarray(rec.sensors.t, dtype=np.float64)
    index, placed_by = frame_grid(np.asarray(rec.sensors.seq, dtype=np.int64), t_frames)
    t_frames, time_scatter, steady = grid_times(index, t_frames)
    n = int(index[-1]) + 1
    if n > MAX_GRID_PER_FRAME * len(index):
        raise DiscrepancyError(
            f"{name}: the {len(index)} sensor frames are spread over {n} frame times ({placed_by}):"
            f" over {1 - 1 / MAX_GRID_PER_FRAME:.0%} of the frames are missing")
    grid = np.arange(n)
    t = np.interp(grid, index, t_frames)
    present = np.zeros(n, dtype=bool)
    present[index] = True
    values = np.asarray(rec.sensors.values, dtype=np.float64)
    ignored = unusable_sensors(values, rec.sensor_names, rec.sensor_units)
    if len(ignored) == len(rec.sensor_names):
        raise DiscrepancyError(f"{name}: no usable sensor: " + "; ".join(
            f"{sensor} {reason}" for sensor, reason in ignored))
    keep = [j for j, sensor in enumerate(rec.sensor_names)
            if sensor not in {s for s, _ in ignored}]
    values = values[:, keep]
    y = np.column_stack([np.interp(grid, index, values[:, j]) for j in range(values.shape[1])])
    t_mocap, raw = mocap_samples(stream)
    if len(t_mocap) < 2:
        raise DiscrepancyError(f"{name}: the mocap joint {joint!r} has fewer than two samples "
                               "with finite angles")
    raw, low_pass_hz = smooth_angles(t_mocap, raw, mocap_low_pass_hz)
    if t_mocap[0] > t[-1] or t_mocap[-1] < t[0]:
        raise DiscrepancyError(
            f"{name}: motion capture ({t_mocap[0]:.6g}–{t_mocap[-1]:.6g} s) and sensors "
            f"({t[0]:.6g}–{t[-1]:.6g} s) do not overlap in time; the workflow needs both on "
            "one clock")
    read = t + mocap_late_s + mocap_skew * (t - t[0])  # the mocap's clock
    inside = (read >= t_mocap[0]) & (read <= t_mocap[-1]) & ~in_mocap_gap(read, t_mocap)
    moving = [k for k in range(raw.shape[1]) if np.ptp(raw[:, k]) > 1e-6]
    if not moving:
        raise DiscrepancyError(f"{name}: the mocap joint {joint!r} never moves")
    angles = np.column_stack([np.interp(read, t_mocap, raw[:, k]) for k in moving])
    finite = np.all(np.isfinite(y), axis=1)
    valid = present & inside & finite
    try:
        floor = sensor_noise(y, valid)
    except DiscrepancyError as err:
        raise DiscrepancyError(f"{name}: {err}") from None
    spread = resampled_spread(y, valid, floor)
    # against the frame-to-frame floor of a stream resampled from a slower sensor, far
    # below its noise, most readings would be spikes
    spiked = spikes(y, valid, _widened(y, valid, floor, spread > RESAMPLED_SPREAD))
    spike_frames = spiked.any(axis=1)
    causes = {"dropped": int((~present).sum()),
              "outside_motion_capture": int((present & ~inside).sum()),
              "not_finite": int((present & inside & ~finite).sum()),
              "spike": int((valid & spike_frames).sum())}
    valid &= ~spike_frames
    span = np.diff(t[[0, -1]])[0] if n > 1 else 0.0
    rate = (n - 1) / span if span > 0 else 0.0
    covered = float(valid.sum()) / rate if rate > 0 else 0.0
    if covered < N_BLOCKS * MIN_BLOCK_S:
        raise DiscrepancyError(
            f"{name}: too short to hold out a block: {math.floor(covered * 100) / 100:.2f} s "
            f"of sensors with motion capture, need at least {N_BLOCKS * MIN_BLOCK_S:.0f} s "
            f"({N_BLOCKS} held-out blocks of {MIN_BLOCK_S:g} s)")
    blocks = held_out_blocks(valid, rate)
    trial = Trial(t=t, y=y, valid=valid, angles=angles,
                  angle_names=tuple(stream.names[k] for k in moving), joint=joint,
                  sensor_names=tuple(rec.sensor_names[j] for j in keep),
                  units=rec.sensor_units, rate_hz=rate, blocks=blocks,
                  scored=valid.copy(), ignored=ignored, spikes=spiked.sum(axis=0),
                  invalid_by_cause=causes,
                  placed_by=placed_by, time_scatter_s=time_scatter, times_steady=steady,
                  mocap_late_s=mocap_late_s,
                  mocap_low_pass_hz=low_pass_hz, mocap_skew=mocap_skew, resampled=spread)
    trial.noise = noise_floor(trial)
    return trial


def invalid_words(by_cause: dict[str, int]) -> str:
    """The invalid frames by cause (:attr:`Trial.invalid_by_cause`) in words, the causes
    that hold none left out: "12 dropped, 3600 outside the motion capture or in its
    dropouts"; "" for none."""
    words = {"dropped": "dropped",
             "outside_motion_capture": "outside the motion capture or in its dropouts",
             "not_finite": "not finite", "spike": "holding an isolated spike"}
    return ", ".join(f"{by_cause[key]} {words[key]}" for key in words if by_cause.get(key))


def held_out_blocks(valid: np.ndarray, rate_hz: float) -> np.ndarray:
    """(N,) int: the fold (0 … ``N_BLOCKS`` − 1) that holds out each grid frame.

    Contiguous blocks of ``BLOCK_S`` seconds are dealt to the folds in turn, so each fold
    holds out stretches spread over the whole recording: a fold's training data cover the
    poses it must predict (no extrapolation in pose space) while every held-out stretch is
    long compared with the noise's correlation (none).

    Blocks are counted in grid time, so frames lost here and there (a lossy link) leave the
    layout of the whole recording; only invalid runs longer than ``SKIPPED_RUN_S`` (a
    dropout, a mocap gap) are not counted, so that every block holds about ``BLOCK_S`` of
    data. Counting valid frames instead stretched each block of a link losing 30 % of its
    frames to 3.6 s: a 30 s recording then dealt 9 stretches to the 8 folds, and the fold
    holding poses no other fold reached made a degree-4 map look like overfitting
    (2.5 mm held out against 0.34 mm on the whole recording). Invalid frames take the fold
    of the frame before them.
    """
    valid = np.asarray(valid, dtype=bool)
    counted = np.ones(len(valid), dtype=bool)
    longest = int(round(SKIPPED_RUN_S * rate_hz))
    for start, stop in true_runs(~valid):
        if stop - start > longest:
            counted[start:stop] = False
    rank = np.maximum(np.cumsum(counted) - 1, 0)
    per_block = max(1, int(round(BLOCK_S * rate_hz)))
    return ((rank // per_block) % N_BLOCKS).astype(np.int64)


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index ranges of the runs of True in the 1-D bool ``mask``, in order."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def frame_grid(seq: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, str]:
    """Each frame's index on the uniform grid, and how it was placed (a short phrase).

    The grid step is the most common increment of ``seq``: 1 for a frame counter (dropped
    frames are the larger increments), k for a counter that counts in steps of k or a
    millisecond clock sampled every k ms. A frame sits at ``round((seq − seq₀) / step)``,
    moved on by one where that would repeat its predecessor's index (a jittering
    millisecond clock). The grid then runs at the device's sampling rate and a dropped
    frame is an empty grid point, whatever the counter counts.

    Where the counter and the frames' times disagree about a gap by ``JUMP_DISAGREE_S`` or
    more (:func:`_gaps_by_time`), the times place the frames after it: a counter that
    jumped leaves no empty grid points, and a device that paused while its counter did not
    count leaves as many as the pause lasted.

    Args:
        seq: (N,) strictly increasing sequence numbers.
        t: (N,) s, the frames' times, increasing.
    """
    increments, counts = np.unique(np.diff(seq), return_counts=True)
    step = int(increments[np.argmax(counts)]) if increments.size else 1
    index = np.round((seq - seq[0]) / step).astype(np.int64)
    order = np.arange(len(seq))
    index = np.maximum.accumulate(index - order) + order  # at least one step per frame
    placed_by = FRAME_COUNTER if step == 1 else f"seq counting {step} per frame" + (
        "" if np.all((seq - seq[0]) % step == 0) else ", rounded")
    steps, moved = _gaps_by_time(index, np.asarray(t, dtype=np.float64))
    if not moved:
        return index, placed_by
    return (np.concatenate([[0], np.cumsum(steps)]).astype(np.int64),
            f"{placed_by}, {moved} gap{'s' if moved > 1 else ''} by the frames' times")


def _gaps_by_time(index: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, int]:
    """(N − 1,) grid steps between consecutive frames, with the gaps the frames' times put
    elsewhere than ``index`` does, and how many of those there are.

    The frame period is the median time per grid step over spans of ``PERIOD_SPAN`` frames.
    Each gap that ``index`` or the times make ``JUMP_DISAGREE_S`` or longer is measured
    on the times: the offset ``t − period × index`` is taken as its median over
    ``JUMP_WINDOW_S`` of frames on either side, and the gap is its step there in frame
    periods plus the step ``index`` takes. Medians over a second keep frames stamped on a
    host's clock as they arrive, late and bunched after the host stalled, from moving the
    gap: they are a minority of either window. The gap is moved when the two disagree by
    ``JUMP_DISAGREE_S`` or more and by a factor of two (a counter that jumped by 1,000 while
    4 ms passed; a pause of a second while it counted one).

    Args:
        index: (N,) grid indices placed by the counter, strictly increasing.
        t: (N,) s, the frames' times.
    """
    steps = np.diff(index)
    period = frame_period(index, t)
    if not period > 0:
        return steps, 0
    shortest = JUMP_DISAGREE_S / period
    offset = t - period * index
    width = max(1, int(round(JUMP_WINDOW_S / period)))
    moved = 0
    for k in np.flatnonzero((steps >= shortest) | (np.diff(t) >= JUMP_DISAGREE_S)):
        before = np.median(offset[max(0, k + 1 - width):k + 1])
        after = np.median(offset[k + 1:k + 1 + width])
        by_time = steps[k] + (after - before) / period
        if (abs(by_time - steps[k]) >= shortest
                and not steps[k] / 2 <= by_time <= 2 * steps[k]):
            steps[k] = max(1, int(round(by_time)))
            moved += 1
    return steps, moved


def frame_period(index: np.ndarray, t: np.ndarray) -> float:
    """The time per grid step, s: the median over spans of ``PERIOD_SPAN`` frames, so a
    dropout or a jump of the counter moves it by nothing and a host's bursts by little;
    NaN for fewer than three frames or non-finite times.

    Args:
        index: (N,) grid indices, strictly increasing; t: (N,) s, the frames' times.
    """
    n = len(index)
    if n < 3 or not np.all(np.isfinite(t)):
        return float("nan")
    span = min(PERIOD_SPAN, n - 1)
    return float(np.median((t[span:] - t[:-span]) / (index[span:] - index[:-span])))


def grid_times(index: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, float, bool]:
    """(N,) s, the frames' times as the grid takes them; how far the recorded ones scatter
    about a steady rate, s RMS; and whether the steady times replaced them.

    A device samples at a steady rate. A host that stamps frames as they arrive (a USB link
    delivers them in bursts) writes many frames with next to the same time and then a
    step: when at least ``BUNCHED_SHARE`` of consecutive frames are stamped within a
    quarter of the frame period of each other, the times are arrival times and the grid
    takes the steady ones instead, ``period × index`` plus an offset that is the straight
    line through the median offsets of the two halves of the recording (so a host clock
    running at another rate, or a stall, moves it by nothing). The motion capture is then
    read at the times the readings were taken, a constant delay before they arrived. A
    hysteresis recording stamped in 16 ms bursts kept 0.197 mm after hysteresis and lag
    (the host's delay, a lag the data cannot tell from one), 0.179 mm with the steady
    times, as with the device's own. Times without bunching are kept as recorded, even
    when they scatter: a device may stamp irregular samples exactly.

    Args:
        index: (N,) grid indices (:func:`frame_grid`); t: (N,) s, the frames' times.
    """
    period = frame_period(index, t)
    if not period > 0:
        return t, 0.0, False
    offset = t - period * index
    half = len(index) // 2
    i1, i2 = np.median(index[:half]), np.median(index[half:])
    o1, o2 = np.median(offset[:half]), np.median(offset[half:])
    trend = o1 + (o2 - o1) / (i2 - i1) * (index - i1)
    scatter = float(np.sqrt(np.mean((offset - trend) ** 2)))
    consecutive = np.diff(index) == 1
    bunched = np.diff(t)[consecutive] < period / 4
    if not consecutive.any() or bunched.mean() < BUNCHED_SHARE:
        return t, scatter, False
    return period * index + trend, scatter, True


def continuous_angles(raw: np.ndarray) -> np.ndarray:
    """(M, A) angles (degrees) without wraps: a step of more than 180° between samples is
    the angle crossing ±180° (or 0°/360°), so whole turns are added to keep it continuous;
    each column is then shifted by whole turns so that its median lies in [−180°, 180°).
    Interpolating across a wrap would sweep the arm through the other way round."""
    unwrapped = np.unwrap(raw, period=360.0, axis=0)
    return unwrapped - 360.0 * np.round(np.median(unwrapped, axis=0) / 360.0)


def smooth_angles(t_mocap: np.ndarray, raw: np.ndarray, cutoff_hz: float | None
                  ) -> tuple[np.ndarray, float | None]:
    """(M, A) the angles ``raw`` low-passed at ``cutoff_hz`` with zero phase, each stretch
    between dropouts (:func:`in_mocap_gap`) on its own, and that cutoff, Hz; the angles
    unchanged and None where ``cutoff_hz`` is None or the motion capture samples too slowly
    for it (``MOCAP_FILTER_MAX_NYQUIST``).

    Args:
        t_mocap: (M,) s, sorted sample times; raw: (M, A) degrees.
    """
    step = mocap_step(t_mocap)
    if (cutoff_hz is None or not np.isfinite(step)
            or cutoff_hz * 2.0 * step >= MOCAP_FILTER_MAX_NYQUIST):
        return raw, None
    sos = butter(MOCAP_FILTER_ORDER, cutoff_hz * 2.0 * step, output="sos")
    breaks = np.flatnonzero(np.diff(t_mocap) > MOCAP_GAP_INTERVALS * step) + 1
    smooth = raw.copy()
    pad = 3 * (2 * len(sos) + 1)  # scipy's default padding, at most
    for run in np.split(np.arange(len(t_mocap)), breaks):
        if len(run) > 2 * MOCAP_FILTER_ORDER:  # too short to filter: kept as sampled
            smooth[run] = sosfiltfilt(sos, raw[run], axis=0, padlen=min(len(run) - 1, pad))
    return smooth, cutoff_hz


def unusable_sensors(values: np.ndarray, names: Sequence[str],
                     units: str) -> tuple[tuple[str, str], ...]:
    """Sensors whose readings cannot be modelled, each with the reason (one short phrase).

    A sensor is unusable when it reads a finite value on fewer than
    ``MIN_SENSOR_COVERAGE`` of the frames (unplugged, overflowing) or never changes (a
    disconnected potentiometer, a stuck channel): neither carries information about the
    movement, and a constant column makes every fit singular.

    Args:
        values: (N, S) readings as recorded.
        names: the S sensor names.
        units: the sensors' unit, for the message.
    """
    out = []
    for j, sensor in enumerate(names):
        column = values[:, j]
        finite = np.isfinite(column)
        if finite.mean() < MIN_SENSOR_COVERAGE:
            out.append((sensor, f"has a finite reading on only {finite.mean():.0%} of frames"))
        elif np.ptp(column[finite]) == 0.0:
            out.append((sensor, f"never changes (constant {column[finite][0]:.6g} {units})"))
    return tuple(out)


def spikes(y: np.ndarray, valid: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """(N, S) bool: valid frames whose reading is an isolated spike (a glitch on the link, a
    contact that opens for a sample), which no model of the suit should chase and which
    would otherwise dominate a root-mean-square gap.

    A reading is a spike when it lies more than ``SPIKE_SIGMAS`` noise standard deviations
    from the median of the ``SPIKE_WINDOW`` frames centred on it. That median follows a
    step, a reversal or the fastest arm move at these rates, so only runs of one or two
    frames that leave and come back are flagged. The noise is the larger of the sensor's
    floor and the same white-noise estimate over the ``SPIKE_NOISE_WINDOW`` frames
    around the reading, so a sensor that is noisier in part of its range keeps that noise.

    Args:
        y: (N, S) readings on the grid (NaN or inf where none was received).
        valid: (N,) frames to examine.
        floor: (S,) the sensors' noise floors (:func:`sensor_noise`).
    """
    finite = np.isfinite(y)
    grid = np.arange(y.shape[0])
    filled = np.column_stack([np.interp(grid, grid[finite[:, j]], y[finite[:, j], j])
                              if finite[:, j].any() else np.zeros(y.shape[0])
                              for j in range(y.shape[1])])
    centre, local = _running_medians(filled.shape, filled.tobytes())
    scale = np.maximum(floor, local)
    return valid[:, None] & finite & (np.abs(filled - centre) > SPIKE_SIGMAS * scale)


@functools.lru_cache(maxsize=2)
def _running_medians(shape: tuple[int, ...], readings: bytes) -> tuple[np.ndarray, np.ndarray]:
    """:func:`spikes`' running medians of the gap-filled readings (``shape``, float64, as
    bytes): their median over ``SPIKE_WINDOW`` frames and the local noise over
    ``SPIKE_NOISE_WINDOW`` frames, both read-only. They depend on the sensors alone, so the
    last two are kept: a recording is read again at every clock and filter tried (16 median
    filters, 1.1 s in the main process, on a four-minute recording whose clock is moved)."""
    filled = np.frombuffer(readings).reshape(shape)
    centre = median_filter(filled, size=(SPIKE_WINDOW, 1), mode="nearest")
    d2 = np.abs(np.diff(filled, 2, axis=0, prepend=filled[:1], append=filled[-1:]))
    local = D2_MAD_TO_SIGMA * median_filter(d2, size=(SPIKE_NOISE_WINDOW, 1), mode="nearest")
    centre.flags.writeable = local.flags.writeable = False
    return centre, local


def spike_counts(sensors: Sequence[str], counts: Sequence[int]) -> str:
    """Isolated spikes per sensor as a phrase, e.g. "F 2, R 1" (sensors without any left
    out), or "none"."""
    named = [f"{sensor} {n}" for sensor, n in zip(sensors, counts, strict=True) if n]
    return ", ".join(named) if named else "none"


def noise_floor(trial: Trial) -> np.ndarray:
    """Per-sensor white-noise standard deviation, in sensor units.

    From second differences of consecutive measured frames: for white noise of variance σ²,
    Δ²y has variance 6σ², while a smooth movement contributes only ``acceleration × dt²``
    (≈ 0.02 mm at 250 Hz for the fastest protocol moves). A robust scale (1.4826 × MAD) keeps
    the few frames at movement onsets from inflating it. This is the lowest held-out RMSE any
    model can reach: the residual left when every systematic effect is explained.

    Readings quantised coarser than their noise (an ADC count, a rounded logger) make most
    second differences exactly zero and the MAD collapse towards 0, yet no model can get
    below the rounding error, whose standard deviation is ``q/√12`` for a step ``q``
    (:func:`quantisation_step`). The floor is the larger of the two.

    The MAD of quantised readings is itself quantised (it moves in half-steps), so for
    readings whose step is coarser than ``QUANTISED_SHARE`` of that estimate the spread
    is the standard deviation of the second differences within ±``D2_CLIP_SIGMAS`` of
    their median instead. It counts the rounding error with the noise, as the residual of
    any model does (σ² + q²/12 while σ ≳ q/2).

    A sensor whose readings change less from one frame to the next than noise can
    (``trial.resampled`` over ``RESAMPLED_SPREAD``: a stream resampled from a slower
    sensor) would have a floor far below its noise; its floor is the widest spread of its
    second differences over 2 to ``RESAMPLED_STRIDES`` frames instead.
    """
    return _widened(trial.y, trial.valid, sensor_noise(trial.y, trial.valid),
                    trial.resampled > RESAMPLED_SPREAD)


def _widened(y: np.ndarray, valid: np.ndarray, floor: np.ndarray, resampled: np.ndarray
             ) -> np.ndarray:
    """``floor`` (S,) with each sensor marked in ``resampled`` (S,) raised to the widest
    spread of its second differences over 2 to ``RESAMPLED_STRIDES`` frames."""
    flagged = np.flatnonzero(resampled)
    if not flagged.size:
        return floor
    wide = np.nanmax([_spread_over(y[:, flagged], valid, k)
                      for k in range(2, RESAMPLED_STRIDES + 1)], axis=0)
    out = floor.copy()
    out[flagged] = np.maximum(floor[flagged], wide)
    return out


def sensor_noise(y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(S,) the noise floor (:func:`noise_floor`) of readings y (N, S) over the valid frames.

    Raises DiscrepancyError when too few frames were received close enough together to
    measure it (``NOISE_TRIPLES_NEEDED``)."""
    d2 = _second_differences(y, valid)
    centred = d2 - np.median(d2, axis=0)
    sigma = D2_MAD_TO_SIGMA * np.median(np.abs(centred), axis=0)
    step = np.array([quantisation_step(y[valid, j]) for j in range(y.shape[1])])
    rounding = step / np.sqrt(12.0)
    for j in np.flatnonzero(step > QUANTISED_SHARE * sigma):
        sigma[j] = _clipped_sd(centred[:, j], max(sigma[j], rounding[j]))
    return np.maximum(sigma, rounding)


def _spread_over(y: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    """(S,) the robust spread of the second differences over k frames of readings y (N, S),
    y[i + 2k] − 2·y[i + k] + y[i] over ``valid`` frames, as the σ of white noise; NaN where
    no such triple is valid."""
    ok = valid[2 * k:] & valid[k:-k] & valid[:-2 * k]
    if not ok.any():
        return np.full(y.shape[1], np.nan)
    y0 = np.where(valid[:, None], y, 0.0)  # invalid frames may hold NaN or inf
    d2 = (y0[2 * k:] - 2.0 * y0[k:-k] + y0[:-2 * k])[ok]
    return D2_MAD_TO_SIGMA * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)


def resampled_spread(y: np.ndarray, valid: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """(S,) per sensor, the widest spread of the second differences of readings y (N, S)
    over k = 2 … ``RESAMPLED_STRIDES`` frames (:func:`_spread_over`), each over k² times
    its noise floor ``floor`` (S,), what a smooth movement without noise can reach: at
    most 1/4 for white noise, at most about 1 for a movement; inf where the floor is 0;
    NaN where no such span is valid."""
    widest = np.full(y.shape[1], np.nan)
    for k in range(2, RESAMPLED_STRIDES + 1):
        widest = np.fmax(widest, _spread_over(y, valid, k) / k**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(floor > 0, widest / floor, np.inf)


def _second_differences(y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(K, S) second differences Δ²y of runs of three valid frames; where there are fewer
    than ``MIN_NOISE_TRIPLES``, also those of successive valid frames i < j < k spanning at
    most ``MAX_NOISE_SPAN`` frame times, on the same scale: the residual of the line through
    frames i and k at j, r = y_j − (a·y_i + b·y_k) with a = (k − j)/(k − i) and b = 1 − a,
    has variance (1 + a² + b²)σ² for white noise, so r·√(6 / (1 + a² + b²)) has Δ²y's 6σ²
    (and is −Δ²y for three frames in a row)."""
    ok = valid[2:] & valid[1:-1] & valid[:-2]
    y0 = np.where(valid[:, None], y, 0.0)  # invalid frames may hold NaN or inf
    d2 = (y0[2:] - 2.0 * y0[1:-1] + y0[:-2])[ok]
    if len(d2) >= MIN_NOISE_TRIPLES:
        return d2
    frames = np.flatnonzero(valid)
    i, j, k = frames[:-2], frames[1:-1], frames[2:]
    spread = (k - j > 1) | (j - i > 1)
    near = spread & (k - i <= MAX_NOISE_SPAN)
    i, j, k = i[near], j[near], k[near]
    a = ((k - j) / (k - i))[:, None]
    r = y[j] - a * y[i] - (1.0 - a) * y[k]
    spanned = r * np.sqrt(6.0 / (1.0 + a ** 2 + (1.0 - a) ** 2))
    d2 = np.concatenate([d2, spanned])
    if len(d2) < NOISE_TRIPLES_NEEDED:
        raise DiscrepancyError(
            f"too few frames received close together to measure the sensors' noise: "
            f"{len(d2)} runs of three within {MAX_NOISE_SPAN} frame times, need "
            f"{NOISE_TRIPLES_NEEDED}")
    return d2


def _clipped_sd(centred: np.ndarray, sigma: float, iterations: int = 5) -> float:
    """White-noise σ from second differences ``centred`` on their median: their standard
    deviation within ±``D2_CLIP_SIGMAS`` of it, the clip re-placed from the σ before
    (starting at ``sigma``), corrected for the variance the clip removes."""
    scale = math.sqrt(6.0) * sigma
    for _ in range(iterations):
        # never empty: the clip is at least 4·1.4826 MADs wide, so half the values are inside
        kept = centred[np.abs(centred) <= D2_CLIP_SIGMAS * scale]
        scale = math.sqrt(float(np.mean(kept ** 2)) / D2_CLIP_VARIANCE)
    return scale / math.sqrt(6.0)


def quantisation_step(values: np.ndarray) -> float:
    """The resolution of one sensor's readings, in sensor units; 0 when they look continuous.

    The smallest gap between distinct readings, ignoring gaps below 1e-9 of the range (float
    round-off between readings converted along different paths). For continuous readings the
    smallest gap shrinks with the number of frames and is negligible against any noise.
    """
    levels = np.unique(values[np.isfinite(values)])
    if len(levels) < 2:
        return 0.0
    gaps = np.diff(levels)
    gaps = gaps[gaps > 1e-9 * (levels[-1] - levels[0])]
    return float(gaps.min()) if len(gaps) else 0.0
