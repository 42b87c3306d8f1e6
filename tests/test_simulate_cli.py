"""``imulog simulate``: files written, options reach the model, clear errors."""

from __future__ import annotations

from click.testing import CliRunner

from imulog.cli import cli
from imulog.simulate import load_truth


def test_simulate_writes_trials_with_truth(tmp_path):
    args = ["simulate", "r2g", "-o", str(tmp_path), "--subjects", "2", "--repetitions", "2", "--seed", "5"]
    args += ["--set", "opening_static_s=2", "--set", "post_wave_static_s=1", "--set", "drift_ppm=40"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    for stem in ("r2g_s00_t00", "r2g_s01_t00"):
        for suffix in ("_imu.csv", "_imu.mapping.json", "_vicon.csv", "_meta.json", "_truth.json", "_truth.npz"):
            assert (tmp_path / f"{stem}{suffix}").is_file()
        truth = load_truth(tmp_path / f"{stem}_truth.json")
        assert len(truth.phases) == 8
        assert truth.alignment["drift_ppm"] == 40
    assert "wrote 2 trial(s)" in result.output


def test_noise_free_flag_and_adc_output(tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "adl", "-o", str(tmp_path), "--noise-free", "--repetitions", "1"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "adl_s00_t00_adc.txt").is_file()
    truth = load_truth(tmp_path / "adl_s00_t00_truth.json")
    assert truth.info["params"]["environment"]["noise_free"] is True
    assert truth.info["params"]["imu"]["quantize"] is False


def test_bad_parameter_is_a_one_line_error(tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "r2g", "-o", str(tmp_path), "--set", "repetitons=2"])
    assert result.exit_code != 0
    assert "repetitons" in result.output and "did you mean repetitions" in result.output
    assert "Traceback" not in result.output
    result = CliRunner().invoke(cli, ["simulate", "r2g", "-o", str(tmp_path), "--set", "novalue"])
    assert result.exit_code != 0 and "NAME=VALUE" in result.output


def test_help_and_parameter_list():
    result = CliRunner().invoke(cli, ["simulate", "--help"])
    assert result.exit_code == 0 and "imulog simulate r2g -o sim/" in result.output
    result = CliRunner().invoke(cli, ["simulate", "slide", "-o", "unused", "--list-parameters"])
    assert result.exit_code == 0
    assert "impact_frequency_hz" in result.output and "drift_ppm" in result.output


def test_unwritable_output_and_mistyped_setting_are_one_line_errors(tmp_path):
    """An output folder that cannot be created used to end in a traceback; a --set value of the wrong type
    gave numpy's message without naming the setting."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = CliRunner().invoke(cli, ["simulate", "r2g", "-o", str(blocker / "sim"), "--repetitions", "1"])
    assert res.exit_code == 1 and f"{blocker / 'sim'}: cannot write" in res.output
    assert not isinstance(res.exception, OSError)
    res = CliRunner().invoke(cli, ["simulate", "r2g", "-o", str(tmp_path / "s"), "--set", "drift_ppm=abc"])
    assert res.exit_code == 1 and "drift_ppm=abc" in res.output and not isinstance(res.exception, TypeError)
