"""A study's workflow on real files of several devices in one folder (the third user audit's walk through README,
docs/batch.md and docs/epochs.md): convert the folder, process epochs, gather the study's epoch table. Real
recordings of ../shared/data/devices: the Axivity AX6 .cwa, two Xsens MTw of one recording, the ActiGraph .gt3x
beside ActiLife's RAW export of it."""

from __future__ import annotations

import shutil

import pandas as pd
import pytest
from click.testing import CliRunner

from imulog.cli import cli


def run(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture(scope="module")
def study(shared_data, tmp_path_factory):
    """The folder converted (one trial per recording) and epochs computed on every IMU by imulog batch."""
    root = tmp_path_factory.mktemp("study")
    raw = root / "raw"
    raw.mkdir()
    devices = shared_data / "devices"
    for f in (
        devices / "axivity_cwa/ax6_sample.cwa",
        devices / "actigraph_gt3x/example.gt3x",
        devices / "actigraph_gt3x/exampleRAW.csv",
        *sorted((devices / "xsens_mtmanager").glob("MT_012005D6_031-000_*.txt")),
    ):
        shutil.copy(f, raw)
    code, text, err = run("convert", raw, "-o", root / "archive")
    assert code == 0, err
    assert text.strip() == f"wrote 3 trial(s) to {root / 'archive'}"  # the RAW export is the .gt3x's recording
    code, text, err = run("batch", root / "archive", "--steps", "epochs", "--no-ledger")
    assert code == 0, text + err
    return root


def test_the_epoch_table_says_which_device_each_row_comes_from(study):
    """A study of several devices compares their epochs; the table had path, subject, trial and imu only, and
    the model and serial had to be looked up trial by trial."""
    out = study / "study_epochs.csv"
    code, text, err = run("catalog", study / "archive", "-o", study / "catalog.parquet", "--epochs", out)
    assert code == 0, err
    table = pd.read_csv(out)
    assert list(table.columns[:6]) == ["path", "subject", "trial", "imu", "device", "serial"]
    devices = table.groupby("imu")[["device", "serial"]].first()
    assert devices.loc["ax6_6011802"].tolist() == ["Axivity AX6", "6011802"]
    assert devices.loc["mt_00b421af"].tolist() == ["Xsens MT", "00B421AF"]
    assert devices.loc["tas1e31150129"].tolist() == ["ActiGraph Link", "TAS1E31150129"]
    assert table["device"].notna().all()


def test_the_epoch_table_times_every_row_and_says_which_clock_is_known(study):
    """The real Xsens MT Manager trial has no start time (``// Start Time: Unknown``): its rows' ``time`` was empty
    and nothing else said when an epoch was; the .cwa's and .gt3x's device clocks (local time, no zone) were
    written as UTC instants. Now ``t[s]`` (seconds since the recording's start) is filled in every row,
    ``local_time`` is the device's wall clock wherever a start time is known, and ``time`` (UTC) only where the
    start has a zone (the .gt3x's info.txt gives -05:00; the .cwa has none)."""
    from imulog.archive import TrialReader

    out = study / "study_epochs_times.parquet"
    code, text, err = run(
        "catalog", study / "archive", "-o", study / "catalog_t.parquet", "--epochs", out, "--epoch-s", 5
    )
    assert code == 0, err
    table = pd.read_parquet(out)
    assert list(table.columns[6:10]) == ["time", "local_time", "t[s]", "t_ns"]
    assert table["t[s]"].notna().all()
    for (path, _imu), rows in table.groupby(["path", "imu"]):
        with TrialReader(path) as trial:
            start = trial.metadata.get("imulog.trial", {}).get("start_time")
        assert rows["t[s]"].min() == 0 and rows["t[s]"].is_monotonic_increasing
        if start is None:  # the Xsens pair
            assert path.endswith("MT_012005D6_031.mcap") and rows["local_time"].isna().all()
            assert len(rows) == 7  # 33.7 s in 5-s epochs
            continue
        begin = pd.Timestamp(start)
        since = pd.to_timedelta(rows["t[s]"], unit="s")
        local = begin.tz_localize(None) + since
        assert (abs(rows["local_time"] - local) < pd.Timedelta("1us")).all(), path
        if begin.tzinfo is None:  # the .cwa: a local clock without a zone is no instant
            assert path.endswith("ax6_sample.mcap") and rows["time"].isna().all()
        else:  # the .gt3x: 08:58 at -05:00 is 13:58 UTC
            assert path.endswith("example.mcap") and str(begin.tzinfo) == "UTC-05:00"
            assert (abs(rows["time"] - (begin.tz_convert("UTC") + since)) < pd.Timedelta("1us")).all()


def test_epochs_at_a_rate_no_epoch_fits_say_how_to_declare_the_nominal_one(shared_data, tmp_path):
    """x-io's Fusion example CSV: time stamps at 99.2125 Hz on average and no declared rate; epochs said only 'the
    calibration epoch of 10 s is not a whole number of samples at 99.2125 Hz'. Now the line says how to declare
    the nominal rate, and the trial converted that way gives its epochs (the stamps unchanged)."""
    from imulog.archive import TrialReader

    csv = shared_data / "imu_text/fusion_sensor_data.csv"
    plain, declared = tmp_path / "plain.mcap", tmp_path / "declared.mcap"
    assert run("convert", csv, "-o", plain)[0] == 0
    result = CliRunner().invoke(cli, ["process", "epochs", str(plain)])
    assert result.exit_code == 1
    line = result.output.strip()
    assert len(line.splitlines()) == 1 and "at 99.2125 Hz" in line, line
    assert "declare it when converting: imulog convert FILE --rate 99" in line, line
    assert run("convert", csv, "--rate", "100", "-o", declared)[0] == 0
    code, text, err = run("process", "epochs", declared)
    assert code == 0, err
    with TrialReader(plain) as a, TrialReader(declared) as b:
        assert (a.read("/imu/imu").t_ns == b.read("/imu/imu").t_ns).all()
        n = len(b.read("/imu/imu").t_ns)
        assert len(b.read("/derived/epochs/5s/imu").t_ns) == -(-n // 500)  # 500 samples an epoch, the last partial


def test_a_failed_step_does_not_stop_the_epochs_of_an_accelerometer_only_wrist(shared_data, tmp_path):
    """The real GENEActiv file (85.7 Hz, accelerometer only) in a batch of orientation, phases and epochs:
    orientation fails (no gyroscope) and, before, the file's epochs were not computed either, though they read
    the raw acceleration only. Now epochs still run; phases, which reads no orientation, runs too and fails on
    its own (no gyroscope); the file is reported failed with both failures and what still ran."""
    from imulog.archive import TrialReader

    trial = tmp_path / "geneactiv.mcap"
    assert run("convert", shared_data / "devices/geneactiv_bin/GENEActiv_testfile.bin", "-o", trial)[0] == 0
    result = CliRunner().invoke(
        cli,
        ["batch", str(trial), "--steps", "orientation,phases,epochs", "--set", "epochs.epochs_s=10,60", "--no-ledger"],
    )
    assert result.exit_code == 1
    failed = [line for line in result.output.splitlines() if line.startswith("FAILED")]
    assert len(failed) == 1 and ": orientation: ValueError:" in failed[0], result.output
    assert "; phases: ValueError: /imu/geneactiv has no gyroscope" in failed[0], failed[0]
    assert failed[0].endswith("(still run: epochs)"), failed[0]
    with TrialReader(trial) as reader:
        topics = reader.topics()
        steps = {r["step"] for r in reader.runs().values()}
    assert "/derived/epochs/10s/geneactiv" in topics and "/derived/epochs/60s/geneactiv" in topics
    assert steps == {"epochs:geneactiv"}


def test_after_a_failed_step_a_step_runs_unless_it_reads_what_failed(shared_data, study, tmp_path):
    """A folder of real wearables (the GENEActiv, accelerometer only, beside the AX6 trial) through the batch
    help's home-monitoring steps: orientation fails on the GENEActiv and, before, its metrics (which read the raw
    acceleration, and phases and trajectories when present) stopped there too; only epochs still ran. One rule
    now (``StepSpec.reads``): a step runs unless a step it reads failed, else it is recorded not run with the
    failed step named (trajectory reads orientation; metrics reads trajectory, so it waits for it)."""
    from imulog.archive import TrialReader
    from imulog.batch import run as batch_run

    folder = tmp_path / "wearables"
    folder.mkdir()
    shutil.copy(study / "archive" / "ax6_sample.mcap", folder)
    trial = folder / "geneactiv.mcap"
    assert run("convert", shared_data / "devices/geneactiv_bin/GENEActiv_testfile.bin", "-o", trial)[0] == 0
    args = ["batch", str(folder), "--steps", "orientation,metrics,epochs", "--set", "epochs.epochs_s=10,60"]
    result = CliRunner().invoke(cli, [*args, "--no-ledger"])
    assert result.exit_code == 1
    failed = [line for line in result.output.splitlines() if line.startswith("FAILED")]
    assert len(failed) == 1 and failed[0].startswith(f"FAILED {trial}: orientation: ValueError:"), result.output
    assert failed[0].endswith("(still run: metrics, epochs)"), failed[0]
    with TrialReader(trial) as reader:
        assert {r["step"] for r in reader.runs().values()} == {"metrics:geneactiv", "epochs:geneactiv"}
        assert reader.metadata["imulog.metrics"]["arm_usage.overall_percent"] >= 0
    with TrialReader(folder / "ax6_sample.mcap") as reader:
        assert {"orientation:ax6_6011802", "metrics:ax6_6011802"} <= {r["step"] for r in reader.runs().values()}

    report = batch_run(
        trial,
        "orientation,trajectory,metrics,epochs",
        options={"epochs": {"epochs_s": "10,60"}},
        progress=False,
        ledger=None,
    )
    (res,) = report.files
    assert res.status == "failed" and res.failed_step == "orientation"
    why = {s.step: (s.skipped, s.reason) for s in res.steps}
    assert why["trajectory"] == (True, "not run: needs orientation, which failed")
    assert why["metrics"] == (True, "not run: needs orientation, which failed")  # through the trajectory
    assert why["epochs"][0]  # up to date from the first batch: it ran, and skipped itself
    assert res.error.endswith(
        "(still run: epochs; trajectory not run: needs orientation, which failed; "
        "metrics not run: needs orientation, which failed)"
    ), res.error


def test_the_batch_help_teaches_a_wearables_study_and_its_line_runs(study):
    """imulog batch --help showed lab lines only (its default steps need an optical reference, so a wearables
    archive failed every file at align); its home-monitoring line now runs as printed on the study's archive."""
    import shlex

    help_text = CliRunner().invoke(cli, ["batch", "--help"]).output
    assert "epochs_s=5,60" in help_text  # the epochs step names its options, not only "EpochParams fields"
    line = next(x for x in help_text.splitlines() if "# home monitoring" in x)
    args = shlex.split(line.split("#")[0].strip())
    assert args[:3] == ["imulog", "batch", "wearables/"]
    result = CliRunner().invoke(cli, ["batch", str(study / "archive"), *args[3:], "--no-ledger"])
    assert result.exit_code == 0, result.output
    assert "3 processed" in result.output or "up to date" in result.output, result.output


def test_view_refuses_its_outputs_before_reading_any_trial(tmp_path):
    """`view a.mcap b.mcap --save study.rrd` (one file for two recordings) and a --save file that exists were
    refused only after every trial had been read (a week's overview takes minutes); docs/cli.md promises outputs
    are refused before reading anything. Files that cannot be read show it: the refusal comes first."""
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for f in (a, b):
        f.write_bytes(b"\x89MCAP0\r\n" + b"not a trial" * 20)
    result = CliRunner().invoke(cli, ["view", str(a), str(b), "--save", str(tmp_path / "study.rrd")])
    assert result.exit_code == 1
    assert "--save" in result.output and "2 trials make 2 recordings" in result.output, result.output
    existing = tmp_path / "a.rrd"
    existing.write_bytes(b"")
    result = CliRunner().invoke(cli, ["view", str(a), "--save", str(existing)])
    assert result.exit_code == 1 and "exists; add --overwrite" in result.output, result.output


def test_info_on_the_study_folder_names_the_catalog(study):
    """`imulog info archive/` said only "Invalid value for 'FILE': File 'archive' is a directory"."""
    result = CliRunner().invoke(cli, ["info", str(study / "archive")])
    assert result.exit_code == 2
    assert "is a folder; info shows one trial" in result.output
    assert f"imulog catalog {study / 'archive'} -o catalog.parquet" in result.output, result.output


def test_export_on_the_reference_clock_of_a_wearable_says_it_has_none(study, tmp_path):
    """The real AX6 trial has no optical system: `export --clock reference` told the user to run
    `imulog process align`, which can only fail on it (no markers or poses). Now it says there is no reference
    clock and names --clock device; nothing is written."""
    out = tmp_path / "ax6.csv"
    trial = study / "archive" / "ax6_sample.mcap"
    args = ["export", str(trial), "-t", "/imu/ax6_6011802", "-o", str(out), "--clock", "reference"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1, result.output
    assert "no /markers/* or /poses/* channel" in result.output and "--clock device" in result.output
    assert "process align" not in result.output and not out.exists()


def test_a_process_step_given_several_trials_or_a_folder_names_imulog_batch(study):
    """`imulog process epochs a.mcap b.mcap` or `... archive/` gave only click's words ('Got unexpected extra
    argument', 'is a directory'); the line now says the step takes one trial and names imulog batch."""
    archive = study / "archive"
    trials = sorted(archive.glob("*.mcap"))
    for args in (["process", "epochs", *trials[:2]], ["process", "orientation", archive]):
        result = CliRunner().invoke(cli, [str(a) for a in args])
        assert result.exit_code == 2
        line = result.output.strip().splitlines()[-1]
        assert f"process {args[1]} runs on one trial" in line and f"imulog batch PATHS... --steps {args[1]}" in line
    result = CliRunner().invoke(cli, ["process", "epochs", "--bogus", str(trials[0])])
    assert result.exit_code == 2 and "imulog batch" not in result.output  # other usage errors unchanged
