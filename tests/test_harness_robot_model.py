"""The committed MuJoCo model of NAO's arms: regenerates byte for byte, matches URDF kinematics."""

import hashlib

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shared_data import SHARED_DIR
from urdf_fk import link_pose, load_joints

from exohil.harness.robot_model import (
    ARM_JOINTS,
    NAO_ARMS_MJCF,
    NAO_DIR,
    NAO_URDF,
    UrdfError,
    build_nao_arms_mjcf,
    main,
)

JOINTS = load_joints(NAO_URDF)
MODEL = mujoco.MjModel.from_xml_path(str(NAO_ARMS_MJCF))
BODIES = [f"{s}{link}" for s in "RL" for link in ("Shoulder", "Bicep", "Elbow", "ForeArm")]
BODIES += ["r_wrist", "l_wrist"]


def test_committed_mjcf_equals_a_regeneration():
    assert NAO_ARMS_MJCF.read_text(encoding="utf-8") == build_nao_arms_mjcf(NAO_URDF)


def test_urdf_copy_is_the_one_named_in_source_md():
    digest = hashlib.sha256(NAO_URDF.read_bytes()).hexdigest()
    assert digest in (NAO_DIR / "SOURCE.md").read_text(encoding="utf-8")
    assert (NAO_DIR / "LICENSE").read_text(encoding="utf-8").startswith("Copyright")
    shared = SHARED_DIR / "robots" / "nao" / "nao_v50.urdf"
    if shared.exists():
        assert shared.read_bytes() == NAO_URDF.read_bytes()


def test_model_has_the_urdf_joints_axes_and_limits():
    names = [MODEL.joint(i).name for i in range(MODEL.njnt)]
    assert names == [f"{s}{j}" for s in "RL" for j in ARM_JOINTS]
    assert [MODEL.actuator(i).name for i in range(MODEL.nu)] == names
    by_name = {j.name: j for j in JOINTS.values()}
    for i, name in enumerate(names):
        assert np.array_equal(MODEL.jnt_range[i], [by_name[name].lower, by_name[name].upper])
        assert np.array_equal(MODEL.jnt_axis[i], by_name[name].axis)
        assert np.array_equal(MODEL.actuator_ctrlrange[i], MODEL.jnt_range[i])


def test_the_mappings_limits_differ_from_the_urdfs_as_docs_robot_md_says():
    """docs/robot.md: NAO_LIMITS are 1.5e-6 rad inside the URDF's for pitch and elbow yaw,
    and 2.3e-7..2.7e-7 rad outside them for roll (it said 'at most 2e-6 rad inside'), less
    than MujocoNao's 1e-6 rad out-of-range tolerance."""
    from exohil.harness.robot_mujoco import LIMIT_TOLERANCE
    from exohil.kinematics.robot import NAO_JOINTS, NAO_LIMITS

    by_name = {j.name: j for j in JOINTS.values()}
    for side, prefix in (("right", "R"), ("left", "L")):
        for k, joint in enumerate(NAO_JOINTS):
            urdf = by_name[prefix + joint]
            inside = [NAO_LIMITS[side][k, 0] - urdf.lower, urdf.upper - NAO_LIMITS[side][k, 1]]
            if joint == "ShoulderRoll":
                assert all(-2.7e-7 <= d <= -2.3e-7 for d in inside), (side, inside)
                assert max(map(abs, inside)) < LIMIT_TOLERANCE
            else:
                assert all(1.5e-6 <= d <= 1.6e-6 for d in inside), (side, inside)


@settings(max_examples=100)
@given(st.lists(st.floats(0.0, 1.0), min_size=8, max_size=8))
def test_mujoco_forward_kinematics_equals_urdf_forward_kinematics(fractions):
    data = mujoco.MjData(MODEL)
    q = {}
    for i in range(MODEL.njnt):
        low, high = MODEL.jnt_range[i]
        data.qpos[MODEL.jnt_qposadr[i]] = q[MODEL.joint(i).name] = low + fractions[i] * (high - low)
    mujoco.mj_kinematics(MODEL, data)
    for body in BODIES:
        rot, pos = link_pose(JOINTS, body, {k: np.asarray(v) for k, v in q.items()})
        assert np.allclose(data.body(body).xpos, pos, atol=1e-12), body
        assert np.allclose(data.body(body).xmat.reshape(3, 3), rot, atol=1e-12), body


def test_rotated_joint_origins_are_converted(tmp_path):
    # NAO's arm joints have rpy = 0; a URDF whose shoulder origin is rotated must still give
    # MuJoCo kinematics equal to the URDF's.
    text = NAO_URDF.read_text(encoding="utf-8")
    marker = '<joint name="RShoulderPitch" type="revolute">'
    head, tail = text.split(marker)
    tail = tail.replace('rpy="0 0 0"', 'rpy="0.3 -0.2 0.5"', 1)
    urdf = tmp_path / "rotated.urdf"
    urdf.write_text(head + marker + tail, encoding="utf-8")
    model = mujoco.MjModel.from_xml_string(build_nao_arms_mjcf(urdf))
    data = mujoco.MjData(model)
    q = {"RShoulderPitch": 0.4, "RShoulderRoll": -0.6, "RElbowYaw": 1.0, "RElbowRoll": 0.5}
    for name, value in q.items():
        data.joint(name).qpos[0] = value
    mujoco.mj_kinematics(model, data)
    joints = load_joints(urdf)
    assert joints["RShoulder"].rpy.tolist() == [0.3, -0.2, 0.5]
    for body in ("RShoulder", "RElbow", "r_wrist"):
        rot, pos = link_pose(joints, body, {k: np.asarray(v) for k, v in q.items()})
        assert np.allclose(data.body(body).xpos, pos, atol=1e-12), body
        assert np.allclose(data.body(body).xmat.reshape(3, 3), rot, atol=1e-12), body


def test_masses_come_from_the_urdf():
    assert MODEL.body("RBicep").mass[0] == pytest.approx(0.15777)
    assert MODEL.body("r_wrist").mass[0] == pytest.approx(0.18533)


def test_cli_writes_the_model_and_rejects_bad_input(tmp_path, capsys):
    out = tmp_path / "arms.xml"
    assert main([str(NAO_URDF), str(out)]) == 0
    assert out.read_text(encoding="utf-8") == NAO_ARMS_MJCF.read_text(encoding="utf-8")
    assert not list(tmp_path.glob("*.tmp"))
    assert main([str(NAO_URDF)]) == 2
    broken = tmp_path / "broken.urdf"
    broken.write_text(NAO_URDF.read_text(encoding="utf-8").replace(
        '<joint name="RElbowYaw"', '<joint name="RElbowYawX"'), encoding="utf-8")
    assert main([str(broken), str(tmp_path / "x.xml")]) == 1
    assert "RElbowYaw missing" in capsys.readouterr().err
    not_xml = tmp_path / "bad.urdf"
    not_xml.write_text("<robot", encoding="utf-8")
    with pytest.raises(UrdfError, match="not XML"):
        build_nao_arms_mjcf(not_xml)


def test_cli_refuses_an_output_it_cannot_or_must_not_write(tmp_path, capsys):
    """OUT = URDF silently replaced the URDF by the MJCF; a folder or a missing folder was a
    traceback. Each is now one error line, exit 1, and nothing is written."""
    urdf = tmp_path / "nao.urdf"
    urdf.write_bytes(NAO_URDF.read_bytes())
    folder = tmp_path / "folder"
    folder.mkdir()
    for out, message in ((urdf, "is the input URDF; refusing to overwrite it"),
                         (tmp_path / "." / "nao.urdf", "refusing to overwrite it"),
                         (folder, "it is a folder"),
                         (tmp_path / "missing" / "arms.xml", "does not exist")):
        capsys.readouterr()
        assert main([str(urdf), str(out)]) == 1, out
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert urdf.read_bytes() == NAO_URDF.read_bytes()
    assert list(folder.iterdir()) == [] and not (tmp_path / "missing").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "nao.urdf"]
