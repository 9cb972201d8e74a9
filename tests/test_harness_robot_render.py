"""Stick-figure pictures of the simulated arm beside the human arm (PNG frames, GIF)."""

import numpy as np
import pytest
from PIL import Image

from exohil.harness.robot_mujoco import MujocoNao
from exohil.harness.robot_render import (
    ArmSample,
    human_upper_arm_direction,
    render_arm_frames,
    sample_robot,
    write_arm_animation,
)


@pytest.mark.parametrize(("pose", "side", "expected"), [
    ((0.0, 0.0), "right", [0.0, 0.0, -1.0]),    # hanging
    ((90.0, 90.0), "right", [1.0, 0.0, 0.0]),   # forward flexion
    ((0.0, 90.0), "right", [0.0, -1.0, 0.0]),   # abduction: out to the right (−Y)
    ((0.0, 90.0), "left", [0.0, 1.0, 0.0]),
])
def test_human_direction_in_the_nao_torso_frame(pose, side, expected):
    assert human_upper_arm_direction(*pose, side=side) == pytest.approx(expected, abs=1e-12)


@pytest.fixture(scope="module")
def samples():
    nao = MujocoNao()  # not started: the hanging start pose, as MuJoCo computes it
    out = [sample_robot(nao, 0.1 * k, 30.0, 20.0 * k) for k in range(3)]
    nao.close()
    return out


def test_frames_are_readable_pngs(samples, tmp_path):
    paths = render_arm_frames(samples, tmp_path / "frames", dpi=40)
    assert [p.name for p in paths] == ["arm_00000.png", "arm_00001.png", "arm_00002.png"]
    for path in paths:
        with Image.open(path) as image:
            assert image.format == "PNG" and image.size == (256, 144)
            image.load()
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [p.name for p in paths]
    # different poses draw different pictures
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_animation_is_a_gif_with_one_frame_per_sample(samples, tmp_path):
    path = write_arm_animation(samples, tmp_path / "arm.gif", fps=5, dpi=40)
    with Image.open(path) as image:
        assert image.format == "GIF" and image.n_frames == 3
    assert [p.name for p in tmp_path.iterdir()] == ["arm.gif"]  # no partial file left


@pytest.mark.parametrize("fps", [6.27, 12.56, 25.0, 3.0])
def test_animation_lasts_its_frames_over_fps_to_10_ms(samples, tmp_path, fps):
    """GIF delays are 10 ms units: one delay of 1000 / fps ms, rounded once, made a 15 s demo
    play in 14.1 s (159.5 ms frames at 150 ms). The rounding is spread over the frames."""
    frames = [samples[k % 3] for k in range(40)]  # no two consecutive frames alike
    path = write_arm_animation(frames, tmp_path / "arm.gif", fps=fps, dpi=30)
    delays = []
    with Image.open(path) as image:
        assert image.n_frames == len(frames)
        for k in range(image.n_frames):
            image.seek(k)
            delays.append(image.info["duration"])
    assert abs(sum(delays) - 1000.0 * len(frames) / fps) <= 5.0
    assert max(delays) - min(delays) <= 10


def test_each_animation_frame_shows_its_own_sample_alone(samples, tmp_path):
    # the moving lines are drawn over a saved background: a frame must not keep the lines of
    # the frame before it, so the same sample draws the same picture wherever it falls
    path = write_arm_animation([samples[0], samples[2], samples[0]], tmp_path / "arm.gif")
    with Image.open(path) as image:
        frames = []
        for k in range(image.n_frames):
            image.seek(k)
            frames.append(np.asarray(image.convert("RGB")))
    assert not np.array_equal(frames[0], frames[1])
    np.testing.assert_array_equal(frames[2], frames[0])


def test_bad_input_is_a_clear_error(samples, tmp_path):
    with pytest.raises(ValueError, match="no samples"):
        render_arm_frames([], tmp_path)
    with pytest.raises(ValueError, match="no samples"):
        write_arm_animation([], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="fps"):
        write_arm_animation(samples, tmp_path / "x.gif", fps=0.0)
    broken = ArmSample(t=0.0, bodies={"torso": np.zeros(3)}, humerus=np.array([1.0, 0, 0]))
    with pytest.raises(ValueError, match="missing"):
        render_arm_frames([broken], tmp_path)
    not_unit = ArmSample(t=0.0, bodies=samples[0].bodies, humerus=np.array([2.0, 0, 0]))
    with pytest.raises(ValueError, match="unit"):
        render_arm_frames([not_unit], tmp_path)
    with pytest.raises(ValueError, match="side"):
        human_upper_arm_direction(0.0, 0.0, side="up")


def test_the_pictures_state_their_units(samples):
    """The stick figures had metre ticks with no unit, and 't = 0.10 s' with no clock."""
    from exohil.harness.robot_render import _Figure

    figure = _Figure(dpi=40)
    figure.draw(samples[1])
    front, side = figure.axes
    assert (front.get_xlabel(), front.get_ylabel()) == ("Y (m)", "Z (m)")
    assert (side.get_xlabel(), side.get_ylabel()) == ("X (m)", "Z (m)")
    assert figure.title.get_text().startswith("device time 0.10 s, right arm")
