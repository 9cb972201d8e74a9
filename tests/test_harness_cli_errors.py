"""Bad paths give one error line and a non-zero exit, never a traceback."""

import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from exohil.harness.cli import main

FIXTURE = "fixtures/paper_protocol.mcap"


@pytest.mark.parametrize("args", [
    ["train", "--model", "ann", FIXTURE, "--out", "{missing}/a.npz"],
    ["evaluate", "fixtures/models/ann.npz", FIXTURE, "--json", "{missing}/m.json"],
    ["demo", "--json", "{missing}/s.json"],
    ["plot", FIXTURE, "--kind", "timeseries", "--out", "{missing}/p.png"],
])
def test_output_in_a_missing_folder_is_refused_before_any_work(tmp_path, args):
    missing = tmp_path / "no" / "such"
    result = CliRunner().invoke(main, [a.format(missing=missing) for a in args])
    assert result.exit_code == 2
    assert "does not exist" in result.output and "Traceback" not in result.output


def test_an_os_error_inside_a_command_is_one_line(tmp_path, monkeypatch):
    # The disk fills up while matplotlib writes the PNG (the folder passed the check).
    from matplotlib.figure import Figure

    def disk_full(self, fname, *args, **kwargs):
        raise OSError(28, "No space left on device", str(fname))

    monkeypatch.setattr(Figure, "savefig", disk_full)
    out = tmp_path / "p.png"
    result = CliRunner().invoke(main, ["plot", FIXTURE, "--kind", "timeseries", "--t1", "1",
                                       "--out", str(out)])
    assert result.exit_code == 1
    assert result.output.startswith(f"Error: {out}: cannot write: No space left on device")
    assert len(result.output.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_training_on_a_mocap_only_recording_is_one_line(tmp_path):
    from exohil.formats.recording import AngleStream, Recording, SensorStream
    from exohil.formats.recording_writer import write_recording

    path = tmp_path / "mocap_only.mcap"
    t = np.arange(50) / 100.0
    write_recording(path, Recording(
        sensor_names=(),
        sensors=SensorStream(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 0))),
        mocap={"shoulder": AngleStream(t, ("elv_angle", "shoulder_elv", "shoulder_rot"),
                                       np.zeros((50, 3)))}))
    result = CliRunner().invoke(main, ["train", "--model", "ann", str(path),
                                       "--out", str(tmp_path / "m.npz")])
    assert result.exit_code == 1
    assert "no sensor frames" in result.output and "Traceback" not in result.output


def test_the_cli_group_turns_os_errors_into_one_line():
    import click

    from exohil.harness.cli import _Group

    @click.group(cls=_Group)
    def group():
        pass

    @group.command()
    def boom():
        raise FileNotFoundError(2, "No such file or directory", "/x/y.mcap")

    result = CliRunner().invoke(group, ["boom"])
    assert result.exit_code == 1
    assert result.output == "Error: /x/y.mcap: No such file or directory\n"


@pytest.mark.parametrize(("args", "message"), [
    (["convert", "--from", "ms", "--to", "nao", "nan", "0", "0"], "is not a finite number"),
    (["import", "csv", FIXTURE, "--rate", "100", "--sensor-cols", "1", "--angle-cols", "0",
      "--delimiter", ";;", "--out", "x.mcap"], "exactly one character"),
])
def test_bad_option_values_name_the_problem(args, message):
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2 and message in result.output


def test_a_time_window_past_the_recording_is_one_line_and_no_empty_plot(tmp_path):
    out = tmp_path / "p.png"
    result = CliRunner().invoke(main, ["plot", FIXTURE, "--kind", "timeseries", "--t0", "5000",
                                       "--t1", "6000", "--out", str(out)])
    assert result.exit_code == 1
    assert "no sensor frame or mocap sample in the chosen time window" in result.output
    assert not out.exists()


@pytest.mark.parametrize("module", ["exohil", "exohil.harness.cli"])
def test_python_dash_m_runs_the_same_command_line(module):
    """`python -m exohil` failed ("is a package and cannot be directly executed") and
    `python -m exohil.harness.cli convert ...` printed nothing and exited 0."""
    import json
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", module, "convert", "--from", "ms", "--to",
                           "isb", "0", "90", "0"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["values"]["elevation"] == pytest.approx(-90.0)
    bad = subprocess.run([sys.executable, "-m", module, "convert", "--from", "ms", "--to",
                          "isb", "0", "nan", "0"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "Error" in bad.stderr


def test_a_command_started_with_stdout_closed_says_so():
    """`exohil convert ... >&-` printed nothing and exited 0: with fd 1 closed Python sets
    sys.stdout to None and click drops every line, so a script took it for success."""
    import os
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "exohil", "convert", "--from", "ms", "--to",
                           "isb", "0", "90", "0"], stderr=subprocess.PIPE, text=True,
                          timeout=120, preexec_fn=lambda: os.close(1))
    assert done.returncode == 1
    assert done.stderr.startswith("Error: standard output is closed")


def test_the_help_loads_no_heavy_library():
    """``exohil --help`` and every command's help read the command modules only: torch,
    matplotlib and scipy.signal (each half a second or more to import) wait for a command
    to run."""
    script = (
        "import sys\n"
        "from click.testing import CliRunner\n"
        "from exohil.harness.cli import main\n"
        "runner = CliRunner()\n"
        "assert runner.invoke(main, ['--help']).exit_code == 0\n"
        "for name in main.list_commands(None):\n"
        "    assert runner.invoke(main, [name, '--help']).exit_code == 0, name\n"
        "heavy = ('torch', 'matplotlib', 'scipy.signal')\n"
        "print(sorted(m for m in sys.modules if m in heavy))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]", out.stdout
