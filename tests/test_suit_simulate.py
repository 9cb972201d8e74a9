"""simulate(), suit profile loading, and the `exohil simulate` / `exohil fixtures` commands."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from shared_data import SHARED_DIR

from exohil.emulators.effects import EffectChain, Gain, Quantization, Saturation
from exohil.emulators.protocols import (
    CALIBRATION_MOVEMENT_S,
    MOCAP_RATE_HZ,
    calibration_protocol,
    mot_trajectory,
    paper_protocol,
)
from exohil.emulators.simulate import geometric_signal, simulate
from exohil.emulators.suit_profile import (
    DEFAULT_PROFILE_PATH,
    PROFILES_DIR,
    ProfileError,
    load_default_profile,
    load_profile,
)
from exohil.formats.recording_reader import read_recording
from exohil.formats.recording_writer import write_recording
from exohil.harness.cli import main

SHOULDER_IK = SHARED_DIR / "realdata" / "shoulder-ik"
needs_shoulder_ik = pytest.mark.skipif(not SHOULDER_IK.is_dir(),
                                       reason="shoulder-ik real data not present")


@pytest.fixture(scope="module")
def profile():
    return load_default_profile()


@pytest.fixture(scope="module")
def protocol():
    return paper_protocol(3)


@pytest.fixture(scope="module")
def recording(protocol, profile):
    return simulate(protocol, profile, seed=3)


def test_ideal_simulation_equals_the_geometry(protocol, profile):
    rec = simulate(protocol, profile, seed=1, effects=EffectChain([]))
    ideal = geometric_signal(protocol, profile)
    np.testing.assert_array_equal(rec.sensors.values, ideal.values)
    np.testing.assert_array_equal(rec.sensors.seq, np.arange(len(ideal.t)))
    np.testing.assert_allclose(np.diff(rec.sensors.t), 1 / 250.0)


def test_recording_layout_and_provenance(recording, profile, protocol):
    assert recording.sensor_names == ("F", "SF", "SR", "R")
    assert recording.sensor_units == "mm" and recording.sensor_rate_hz == 250.0
    mocap = recording.mocap["shoulder"]
    assert len(mocap) == 29551
    np.testing.assert_allclose(np.diff(mocap.t), 1 / MOCAP_RATE_HZ)
    assert mocap.names == ("elv_angle", "shoulder_elv", "shoulder_rot")
    assert [s.name for s in recording.segments] == [s.name for s in protocol.segments]
    meta = recording.metadata
    assert meta["seed"] == "3" and meta["suit_profile"] == "default"
    assert meta["suit_profile_sha256"] == profile.sha256()
    assert EffectChain.from_dicts(__import__("json").loads(meta["effect_chain"])).to_json() == \
        profile.effects.to_json()
    assert meta["trajectory"] == "paper_protocol seed=3"


def test_dropped_frames_leave_sequence_gaps(recording):
    seq = recording.sensors.seq
    gaps = np.diff(seq)
    assert gaps.min() == 1 and gaps.max() > 1
    assert len(seq) < 61565 and seq[-1] <= 61564
    assert np.all(np.diff(recording.sensors.t) > 0)


def test_every_effect_changes_the_readings(protocol, profile):
    ideal = simulate(protocol, profile, seed=3, effects=EffectChain([])).sensors.values
    full = simulate(protocol, profile, seed=3)
    kept = full.sensors.seq
    assert np.abs(full.sensors.values - ideal[kept]).mean() > 0.1
    for kind in ("hysteresis", "creep", "saturation", "lag", "drift", "noise", "quantization"):
        without = simulate(protocol, profile, seed=3, effects=profile.effects.without(kind))
        assert not np.array_equal(without.sensors.values, full.sensors.values), kind


def test_simulation_is_deterministic_per_seed(protocol, profile, recording):
    again = simulate(protocol, profile, seed=3)
    np.testing.assert_array_equal(again.sensors.values, recording.sensors.values)
    other = simulate(protocol, profile, seed=4)
    assert not np.array_equal(other.sensors.seq, recording.sensors.seq)


def test_recording_round_trips_through_mcap(recording, tmp_path):
    path = tmp_path / "sim.mcap"
    write_recording(path, recording)
    back = read_recording(path)
    np.testing.assert_array_equal(back.sensors.seq, recording.sensors.seq)
    np.testing.assert_allclose(back.sensors.values, recording.sensors.values, atol=1e-4)
    assert [(s.name, s.t0, s.t1) for s in back.segments] == \
        [(s.name, s.t0, s.t1) for s in recording.segments]
    assert back.metadata["effect_chain"] == recording.metadata["effect_chain"]


# --- profiles ---------------------------------------------------------------------------

def write_profile(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "p.toml"
    path.write_text(text, encoding="utf-8")
    return path


def default_text() -> str:
    return DEFAULT_PROFILE_PATH.read_text(encoding="utf-8")


@pytest.mark.parametrize(("edit", "message"), [
    (lambda s: s.replace('schema = "exohil-suit-profile"', 'schema = "other"'), "'schema'"),
    (lambda s: s.replace("version = 1", "version = 2"), "unsupported profile version"),
    (lambda s: s.replace("radius_mm = 55.0", "radius_mm = -1.0"), "radius_mm"),
    (lambda s: s.replace('name = "SF"', 'name = "F"'), "unique"),
    (lambda s: s.replace("[-100.0, -150.0, -60.0]", "[-100.0, -150.0]"), "thorax_points_mm"),
    (lambda s: s.replace("[80.0, 40.0, -40.0]", "[10.0, 10.0, 0.0]"), "outside the shoulder cap"),
    (lambda s: s.replace("sigma_mm = 0.15", "sigma = 0.15"), "unknown parameter"),
    (lambda s: s.replace('kind = "creep"', 'kind = "glue"'), "unknown effect kind"),
    (lambda s: s.replace("lower_mm = [455.0, 522.0, 478.0, 420.0]", "lower_mm = [1.0, 2.0]"),
     "list of 4 values"),
    (lambda s: s + "\n[[tendon]]\nname = 'X'\n", "missing key 'thorax_points_mm'"),
    (lambda s: s + "\nthis is not toml", "not a readable TOML"),
    (lambda s: s.replace("radius_mm = 55.0", "radius_mm = 55.0\nradius = 1.0"),
     r"\[cap\]: unknown key\(s\) radius"),
    (lambda s: s.replace("[[effect]]", "[[efect]]", 1), r"profile: unknown key\(s\) efect"),
    # TOML has nan and inf: they turned every reading into NaN (or, through the ADC's
    # clipping, into garbage) instead of an error naming the parameter
    (lambda s: s.replace("gain = 0.03", "gain = nan"),
     r"\[\[effect\]\] #3: creep: gain must be a finite number"),
    (lambda s: s.replace("tau_build_s = 15.0", "tau_build_s = inf"),
     "tau_build_s must be a finite"),
    (lambda s: s.replace("clock_offset_s = 0.012", "clock_offset_s = nan"),
     "clock_offset_s must be a finite"),
    (lambda s: s.replace("tau_s = 0.03", "tau_s = inf"), "lag: tau_s must be a finite"),
    (lambda s: s.replace("sigma_mm = 0.15", "sigma_mm = inf"), "sigma_mm must be a finite"),
    (lambda s: s.replace("lower_mm = [455.0, 522.0,", "lower_mm = [nan, 522.0,"),
     "lower_mm must be a finite"),
    (lambda s: s.replace("zero_mm = 0.0", "zero_mm = -inf"), "zero_mm must be a finite"),
    (lambda s: s.replace("mean_burst_frames = 2.0", "mean_burst_frames = inf"),
     "mean_burst_frames must be a finite"),
    (lambda s: s.replace("rate = 0.002", "rate = 'x'"), "rate must be a number"),
    (lambda s: s.replace("operators = 4", "operators = true"), "operators must be a number"),
    # tables and values of the wrong type were "unexpected" tracebacks
    (lambda s: s.replace("centre_mm = [0.0, 0.0, 0.0]", "centre_mm = 'x'"),
     r"\[cap\] centre_mm must be"),
    (lambda s: s.replace("centre_mm = [0.0, 0.0, 0.0]", "centre_mm = [nan, 0.0, 0.0]"),
     r"\[cap\] centre_mm must be"),
    (lambda s: s.replace("radius_mm = 55.0", "radius_mm = inf"), "radius_mm must be a positive"),
    (lambda s: s.replace("[cap]\ncentre_mm = [0.0, 0.0, 0.0]\nradius_mm = 55.0", "cap = 3"),
     r"\[cap\]: expected a table"),
    (lambda s: s.replace('description = "', 'tendon = [1]\ndescription = "').split("[[tendon]]")[0],
     r"\[\[tendon\]\] #1: expected a table"),
    # TOML's true and 1.0 compare equal to 1, so they passed as version 1; an empty tendon
    # name made a channel without a name; an [[effect]] that is not a list was read key by key
    (lambda s: s.replace("version = 1", "version = true"), "unsupported profile version True"),
    (lambda s: s.replace("version = 1", "version = 1.0"), "unsupported profile version 1.0"),
    (lambda s: s.replace('name = "default"', 'name = "  "'), "'name' must be a non-empty"),
    (lambda s: s.replace('name = "SR"', 'name = ""'),
     r"\[\[tendon\]\] #3: name must be a non-empty string, got ''"),
    (lambda s: s.replace('name = "SR"', 'name = 7'),
     r"\[\[tendon\]\] #3: name must be a non-empty string, got 7"),
    (lambda s: s.replace('description = "', 'effect = 3\ndescription = "').split("[[effect]]")[0],
     "'effect' must be a list of \\[\\[effect\\]\\] tables, got int"),
])
def test_bad_profiles_give_one_clear_error(tmp_path, edit, message):
    path = write_profile(tmp_path, edit(default_text()))
    with pytest.raises(ProfileError, match=message) as info:
        load_profile(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_missing_profile_file(tmp_path):
    with pytest.raises(ProfileError, match="no such suit profile"):
        load_profile(tmp_path / "absent.toml")


def test_profile_hash_ignores_formatting_but_not_content(tmp_path, profile):
    reformatted = write_profile(tmp_path, "# a comment\n" + default_text())
    assert load_profile(reformatted).sha256() == profile.sha256()
    changed = write_profile(tmp_path, default_text().replace("sigma_mm = 0.15", "sigma_mm = 0.2"))
    assert load_profile(changed).sha256() != profile.sha256()


def test_profile_with_any_number_of_tendons(tmp_path):
    text = default_text()
    start = text.index('[[tendon]]\nname = "SF"')
    end = text.index("# Effect chain")
    two = text[:start] + text[end:]
    two = two.replace("lower_mm = [455.0, 522.0, 478.0, 420.0]", "lower_mm = 458.0")
    two = two.replace("width_mm = [4.0, 3.0, 3.0, 4.0]", "width_mm = 3.0")
    profile = load_profile(write_profile(tmp_path, two))
    assert profile.sensor_names == ("F",)
    rec = simulate(paper_protocol(1), profile, seed=1)
    assert rec.sensors.values.shape[1] == 1


def test_simulate_warns_when_the_suit_has_more_sensors_than_the_wire_carries(tmp_path):
    """A 17-tendon suit was simulated without a word, and then `exohil emulate` refused the
    recording ("values must be (N>0, 1..16) mm")."""
    text = default_text()
    start, end = text.index("[[tendon]]"), text.index("# Effect chain")
    tendons = text[start:end].split("[[tendon]]")[1:]
    extra = "".join("[[tendon]]" + tendons[i % 4].replace('name = "', f'name = "{i}', 1)
                    for i in range(17))
    noise = '[[effect]]\nkind = "noise"\nsigma_mm = 0.1\n'
    results = {}
    for count, body in ((4, text[start:end]), (17, extra)):
        path = tmp_path / f"suit{count}.toml"
        path.write_text(text[:start] + body + noise, encoding="utf-8")
        results[count] = CliRunner().invoke(main, [
            "simulate", "--protocol", "calibration", "--profile", str(path),
            "--out", str(tmp_path / f"suit{count}.mcap")])
        assert results[count].exit_code == 0, results[count].output
    assert "a wire protocol v1 frame carries at most 16" in results[17].stderr
    assert "17 sensors" in results[17].stderr
    assert "carries at most" not in results[4].stderr
    assert read_recording(tmp_path / "suit17.mcap").sensors.values.shape[1] == 17


DONNING_B = PROFILES_DIR / "donning-b.toml"


@pytest.fixture(scope="module")
def donning_b():
    return load_profile(DONNING_B)


def test_donning_b_is_the_default_suit_with_a_gain_after_the_stops(donning_b, profile):
    assert donning_b.name == "donning-b"
    assert donning_b.sensor_names == profile.sensor_names == ("F", "SF", "SR", "R")
    kinds = [e.name for e in donning_b.effects.effects]
    assert [k for k in kinds if k != "gain"] == [e.name for e in profile.effects.effects]
    assert kinds.index("gain") == kinds.index("saturation") + 1
    gain = next(e for e in donning_b.effects.effects if isinstance(e, Gain))
    assert len(gain.gain) == len(gain.offset_mm) == 4
    assert donning_b.geometry.cap_radius_mm != profile.geometry.cap_radius_mm
    for ours, theirs in zip(donning_b.geometry.tendons, profile.geometry.tendons, strict=True):
        for pts in ("thorax_points_mm", "humerus_points_mm"):
            moved = np.linalg.norm(getattr(ours, pts) - getattr(theirs, pts), axis=1)
            assert np.all((moved >= 8.0) & (moved <= 15.0)), (ours.name, pts, moved)


def test_donning_b_reads_differently_from_default_on_the_same_movement(donning_b, profile,
                                                                        protocol):
    ideal_b = geometric_signal(protocol, donning_b).values
    ideal_default = geometric_signal(protocol, profile).values
    shape = (ideal_b - ideal_default) - (ideal_b - ideal_default).mean(axis=0)
    assert np.all(np.sqrt(np.mean(shape**2, axis=0)) > 3.0)  # not just an offset
    no_drops = profile.effects.without("dropout")
    ours = simulate(protocol, donning_b, seed=3, effects=donning_b.effects.without("dropout"))
    theirs = simulate(protocol, profile, seed=3, effects=no_drops)
    assert np.all(np.mean(np.abs(ours.sensors.values - theirs.sensors.values), axis=0) > 5.0)


def test_donning_b_stays_within_its_stops_and_the_adc_range(donning_b, protocol):
    values = simulate(protocol, donning_b, seed=3).sensors.values
    chain = {e.name: e for e in donning_b.effects.effects}
    adc = chain["quantization"]
    gain, stops = chain["gain"], chain["saturation"]
    assert isinstance(adc, Quantization) and isinstance(gain, Gain)
    assert isinstance(stops, Saturation)
    top = adc.zero_mm + adc.travel_mm * (1 - 2.0**-adc.bits)
    assert values.min() > adc.zero_mm + 50.0 and values.max() < top - 50.0
    stop_reading = np.asarray(gain.gain) * np.asarray(stops.lower_mm) + np.asarray(gain.offset_mm)
    at_stop = np.abs(values - stop_reading) < 1.0
    assert np.all(at_stop.mean(axis=0) < 0.1)
    for j in range(values.shape[1]):  # and nowhere else pinned either
        assert np.mean(values[:, j] <= values[:, j].min() + 0.5) < 0.1
        assert np.mean(values[:, j] >= values[:, j].max() - 0.5) < 0.1


# --- CLI -------------------------------------------------------------------------------

@needs_shoulder_ik
def test_simulate_command_writes_a_readable_recording(tmp_path):
    out = tmp_path / "real.mcap"
    result = CliRunner().invoke(main, ["simulate", "--protocol", f"mot:{SHOULDER_IK / 'ABD02.mot'}",
                                       "--seed", "2", "--without", "dropout", "--out", str(out)])
    assert result.exit_code == 0, result.output
    rec = read_recording(out)
    assert rec.segments[0].name == "ABD02"
    np.testing.assert_array_equal(np.diff(rec.sensors.seq), 1)  # dropout removed
    expected = simulate(mot_trajectory([SHOULDER_IK / "ABD02.mot"]), load_default_profile(), 2,
                        effects=load_default_profile().effects.without("dropout"))
    np.testing.assert_allclose(rec.sensors.values, expected.sensors.values, atol=1e-4)


@pytest.mark.parametrize("profile_args", [[], ["--profile", str(DONNING_B)]],
                         ids=["default", "donning-b"])
def test_simulate_command_writes_a_calibration_recording(tmp_path, profile_args):
    out = tmp_path / "calibration.mcap"
    result = CliRunner().invoke(main, ["simulate", "--protocol", "calibration", "--seed", "3",
                                       *profile_args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    rec = read_recording(out)
    mocap = rec.mocap["shoulder"]
    assert len(mocap) == 60 * 120 and mocap.t[-1] == pytest.approx(60.0 - 1 / 120)
    assert 0.99 * 60 * 250 < len(rec.sensors) <= 60 * 250  # a few frames dropped
    assert [s.name for s in rec.segments] == list(CALIBRATION_MOVEMENT_S)
    assert rec.segments[0].t0 == 0.0 and rec.segments[-1].t1 == pytest.approx(60.0)
    assert rec.metadata["trajectory"] == "calibration_protocol seed=3 duration_s=60"
    profile = load_profile(DONNING_B) if profile_args else load_default_profile()
    assert rec.metadata["suit_profile"] == profile.name
    expected = simulate(calibration_protocol(3), profile, 3)
    np.testing.assert_array_equal(rec.sensors.seq, expected.sensors.seq)
    np.testing.assert_allclose(rec.sensors.values, expected.sensors.values, atol=1e-4)
    np.testing.assert_allclose(mocap.angles, expected.mocap["shoulder"].angles, atol=1e-4)
    # donning-b's SF runs past the wire's 655.35 mm: the emulator would clip it, so say so
    beyond = (rec.sensors.values > 655.35).mean(axis=0)
    warned = "warning: readings outside the wire's 0..655.35 mm on " in result.output
    assert warned == bool(profile_args) == (beyond[1] > 0.3)
    if warned:
        assert f"SF {100 * beyond[1]:.1f} %" in result.output


@pytest.mark.parametrize(("args", "message"), [
    (["--protocol", "walk"], "use 'paper', 'calibration', 'mot:FILE[,FILE...]' or 'replay:FILE'"),
    (["--protocol", "calibration:45"], "use 'paper', 'calibration', 'mot:FILE"),
    (["--protocol", "mot:/nonexistent.mot"], "no such .mot file"),
    (["--protocol", "replay:"], "no such recording: ''"),
    (["--protocol", "replay:/nonexistent.mcap"], "no such recording: '/nonexistent.mcap'"),
    (["--without", "glue"], "unknown effect kind"),
    (["--profile", "/nonexistent.toml"], "does not exist"),
])
def test_simulate_command_bad_input_is_one_clear_error(tmp_path, args, message):
    result = CliRunner().invoke(main, ["simulate", *args, "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code != 0
    assert message in result.output
    assert "Traceback" not in result.output


@needs_shoulder_ik
@pytest.mark.slow
def test_committed_fixtures_rebuild_bit_identically():
    result = CliRunner().invoke(main, ["fixtures", "build", "--check",
                                       "--shoulder-ik", str(SHOULDER_IK)])
    assert result.exit_code == 0, result.output
    from exohil.harness.fixture_specs import FIXTURES

    assert f"all {len(FIXTURES)} fixtures match" in result.output


@needs_shoulder_ik
def test_fixture_check_fails_on_a_wrong_hash(tmp_path):
    fixtures = Path(__file__).resolve().parents[1] / "fixtures"
    (tmp_path / "SHA256SUMS").write_text(
        (fixtures / "SHA256SUMS").read_text().replace("a", "b", 1), encoding="utf-8")
    for name in ("paper_protocol.mcap", "real_motion_abd_flx.mcap"):
        (tmp_path / name).write_bytes((fixtures / name).read_bytes())
    # the real motion named as needs_shoulder_ik found it: the command's default lies beside
    # the package, where an installed one (tox) has none
    result = CliRunner().invoke(main, ["fixtures", "build", "--check", "--dir", str(tmp_path),
                                       "--shoulder-ik", str(SHOULDER_IK)])
    assert result.exit_code == 1, result.output
    assert "MISMATCH paper_protocol.mcap: rebuilt sha256" in result.output  # its "a" changed
    # one not copied: was "committed file differs from its rebuild"
    assert f"MISMATCH paper_protocol_heldout.mcap: missing from {tmp_path}" in result.output


def test_a_build_that_fails_half_way_leaves_the_fixtures_folder_as_it_was(tmp_path):
    """Without the real motion the third fixture cannot be built: the two built before it
    are not written beside the old sums, and the error is one line."""
    fixtures, empty = tmp_path / "fixtures", tmp_path / "no-motion"
    fixtures.mkdir()
    empty.mkdir()
    (fixtures / "SHA256SUMS").write_text("kept\n", encoding="utf-8")
    result = CliRunner().invoke(main, ["fixtures", "build", "--dir", str(fixtures),
                                       "--shoulder-ik", str(empty)])
    assert result.exit_code == 1
    assert "Traceback" not in result.output and "see --shoulder-ik" in result.output
    assert sorted(p.name for p in fixtures.iterdir()) == ["SHA256SUMS"]
    assert (fixtures / "SHA256SUMS").read_text(encoding="utf-8") == "kept\n"


def test_fixtures_list_gives_the_path_of_every_bundled_recording_and_model():
    """An installed exohil keeps its fixtures inside the package, where the README's
    repository paths do not reach: `fixtures list` prints where each one is."""
    from exohil.harness.fixture_specs import FIXTURES
    from exohil.harness.paths import FIXTURES_DIR, MODELS_DIR

    result = CliRunner().invoke(main, ["fixtures", "list"])
    assert result.exit_code == 0, result.output
    rows = dict(line.split("\t", 1) for line in result.output.splitlines())
    for spec in FIXTURES:
        assert rows[str((FIXTURES_DIR / spec.filename).absolute())] == \
            f"recording: {spec.description}"
    for name in ("ennet", "ann"):
        assert rows[str((MODELS_DIR / f"{name}.npz").absolute())].startswith(
            f"reference model {name} ")
    assert all(Path(path).is_file() for path in rows)


def test_fixtures_list_with_an_empty_folder_says_where_it_looked(tmp_path):
    env = {**os.environ, "EXOHIL_FIXTURES": str(tmp_path)}
    exohil = Path(sys.executable).parent / "exohil"  # a new process reads $EXOHIL_FIXTURES
    done = subprocess.run([str(exohil), "fixtures", "list"], env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert f"no recording or model in {tmp_path}" in done.stderr
