"""The simulated stand-in for the held-out 5-segment chain recording (issue 32), through the command line.

:func:`imulog.simulate.chain.write_chain` writes the two CSV files (five IMUs at 40 Hz in one file without a time
column, 20 markers at 30 Hz with one column per marker axis) and a mapping file beside each; this converts them,
then per segment runs orientation, align (the cluster searched among all 20 markers), phases, trajectory and
evaluate, and prints one row per segment: the markers found, the alignment grade, the rests kept of the
still-gyroscope time, the start of ZUPT's assumption line, the largest rotating-bias component and whether it was
applied, and the median / 90th percentile error (cm, x/y/z, mean over windows) of ZUPT and the dedrift baseline.

    python benchmarks/chain_standin.py      # ~2 min on a loaded machine
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli
from imulog.simulate.chain import SEGMENTS, write_chain


def main() -> int:
    d = Path(tempfile.mkdtemp(prefix="chain_"))
    imu_csv, mk_csv, _ = write_chain(d)
    r = CliRunner()
    res = r.invoke(cli, ["convert", str(imu_csv), str(mk_csv), "-o", str(d / "chain.mcap")])
    if res.exit_code:
        raise SystemExit(res.output)
    print(
        "| segment | markers found | alignment | rest kept of still gyroscope (s) | zupt's assumption line | "
        "largest bias (m/s^2) | zupt median / p90 (cm) | dedrift median / p90 (cm) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for k in range(1, SEGMENTS + 1):
        trial, imu = d / f"seg{k}.mcap", f"seg{k}"
        shutil.copyfile(d / "chain.mcap", trial)
        for args in (
            ["process", "orientation", str(trial), "--imu", imu],
            ["process", "align", str(trial), "--imu", imu, "--markers", "markers"],
            ["process", "phases", str(trial), "--imu", imu],
        ):
            res = r.invoke(cli, args)
            if res.exit_code:
                raise SystemExit(res.output)
        out = r.invoke(cli, ["process", "trajectory", str(trial), "--imu", imu]).output
        r.invoke(cli, ["evaluate", str(trial)])
        with TrialReader(trial) as t:
            al, rec = t.metadata["imulog.alignment"], t.metadata["imulog.trajectory"]
            ev = t.metadata["imulog.evaluation"]
        line = next((x.split("zupt: ", 1)[1] for x in out.splitlines() if "assumption failed: zupt:" in x), "ok")
        errors = rec.get("accelerometer_errors", {})
        bias = max((abs(v) for v in errors.get("bias_mps2", [0.0])), default=0.0)

        def fig(m: str, q: str, ev: dict = ev) -> str:
            return "/".join(f"{ev['methods'][m]['summary'][a][q]['mean']:.0f}" for a in "xyz")

        markers = ",".join(x.split(":")[-1] for x in al["cluster"]["markers"])
        print(
            f"| {imu} | {markers} | {al['quality']} | {rec['rests']['rest_s']:.1f} of {rec['rests']['static_s']:.1f} | "
            f"{line.split(';')[0]} | {bias:.2f} ({'applied' if errors.get('applied') else 'refused'}) | "
            f"{fig('zupt', 'median_cm')} / {fig('zupt', 'p90_cm')} | "
            f"{fig('dedrift', 'median_cm')} / {fig('dedrift', 'p90_cm')} |"
        )
    shutil.rmtree(d)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
