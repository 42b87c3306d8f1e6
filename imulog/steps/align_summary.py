"""Human-readable lines about an ``imulog.alignment`` record: plain formatting, no numpy (``imulog info``)."""

from __future__ import annotations


def alignment_summary(record: dict) -> list[str]:
    """Human-readable lines about an ``imulog.alignment`` record (``imulog info``, ``process align``)."""
    if not record:
        return []
    lines = []
    unc = record.get("offset_uncertainty_ns")
    dunc = record.get("drift_uncertainty_ppm")
    off = int(record.get("offset_ns", 0)) / 1e9
    drift = float(record.get("drift_ppm") or 0.0)
    lines.append(
        f"offset {off:.4f} s{f' ± {unc / 1e6:.2f} ms' if unc is not None else ''}, drift {drift:.1f} ppm"
        f"{f' ± {dunc:.1f}' if dunc is not None else ''}"
        f"{'' if record.get('drift_estimated', True) else ' (not estimated)'}, score {float(record.get('score') or 0):.3f}"
        f", signal {record.get('signal', 'angular-velocity-norm')}"
    )
    c = record.get("cluster") or {}
    if c.get("pose"):
        vm = c.get("vector_match")
        frac = c.get("valid_fraction")
        lines.append(
            f"rigid body {c['pose']} (its orientations"
            f"{f', {100 * frac:.1f} % valid' if frac is not None else ''}"
            f"{f', vector match {vm:.3f}' if vm is not None else ''})"
        )
    if c.get("markers"):
        vm, rig = c.get("vector_match"), c.get("rigidity_mm")
        lines.append(
            f"markers {','.join(c['markers'])} ({c.get('selection', 'given')}"
            f"{f', vector match {vm:.3f}' if vm is not None else ''}"
            f"{f', rigid to {rig:.2f} mm' if rig is not None else ''})"
        )
        ru = c.get("runner_up")
        if ru:
            vm2 = ru.get("vector_match")
            lines.append(
                f"runner-up {','.join(ru['markers'])} (ncc {ru.get('ncc')}"
                f"{f', vector match {vm2:.3f}' if vm2 is not None else ''})"
            )
        rej = c.get("rejected_cluster")
        if rej:
            lines.append(
                f"best rigid set {','.join(rej['markers'])} rejected (vector match {rej.get('vector_match')}): "
                "aligned on one marker's acceleration"
            )
    wins = record.get("windows") or []
    used = [w for w in wins if w.get("used")]
    if wins:
        res = [abs(w.get("residual_ns", 0)) / 1e6 for w in used]
        spread = record.get("residual_spread_ns")
        lines.append(
            f"windows {len(used)}/{len(wins)} used, residual lag max {max(res) if res else float('nan'):.2f} ms"
            f"{f', spread {spread / 1e6:.2f} ms' if spread is not None else ''}"
        )
    quality = record.get("quality")
    if quality:
        reasons = record.get("quality_reasons") or []
        lines.append(f"quality {quality}{': ' + '; '.join(reasons) if reasons else ''}")
    return lines


def setup_lines(record: dict) -> list[str]:
    """Lines about a whole setup's alignment (``imulog.alignment["setup"]``): one per IMU, then the clocks."""
    setup = record.get("setup") or {}
    lines = []
    for name, r in setup.items():
        if r.get("quality") == "failed":  # an IMU the setup could not align: why, and no clock
            lines.append(f"{name}: not aligned ({r.get('why') or 'failed'})")
            continue
        off = r.get("offset_ms")
        own = r.get("own_offset_ms")
        unpaired = name in (record.get("unpaired") or {})  # rigid bodies: no body turns like this IMU
        markers = ",".join(r.get("markers") or []) or (
            f"rigid body {r['pose']}" if r.get("pose") else ("no rigid body" if unpaired else "no cluster")
        )
        vm = r.get("vector_match")
        rej = r.get("rejected_markers")
        # an IMU aligned on its own (--imu, a rigid body) has its own clock fit: its drift is on its line
        clock = (
            f"{r['clock']} clock" if r.get("clock") else f"own clock, drift {float(r.get('drift_ppm') or 0):.1f} ppm"
        )
        if r.get("clock_of"):  # no cluster or body of its own: whose clock it took
            clock += f" of {', '.join(r['clock_of'])}"
        lines.append(
            f"{name}: offset {'-' if off is None else f'{off:.2f} ms'} ({clock}"
            f"{'' if own is None else f', own windows {own:.2f} ms'}), {markers}"
            f"{'' if vm is None else f' (vector match {vm:.3f})'}"
            f"{(', dropped ' + ','.join(rej)) if rej else ''}"
            f"{', no frame alignment' if r.get('frame_alignment') is False else ''}, quality {r.get('quality')}"
        )
    for name, why in (record.get("unpaired") or {}).items():  # rigid bodies: IMUs no body turns like
        if name not in setup:
            lines.append(f"{name}: not aligned ({why})")
    if not record.get("clock"):  # every aligned IMU on its own clock (rigid bodies): no setup clock to show
        return lines
    drift = record.get("drift_ppm")
    unc = record.get("drift_uncertainty_ppm")
    note = record.get("drift_note")
    lines.append(
        f"drift {float(drift or 0):.1f} ppm{f' ± {unc:.1f}' if unc is not None else ''}"
        f"{'' if record.get('drift_estimated') else ' (not estimated)'}" + (f": {note}" if note else "")
    )
    groups = (record.get("search") or {}).get("recordings") or []
    if groups:
        lines.append("recordings (one clock each): " + "; ".join(", ".join(g) for g in groups))
    return lines


def setup_summary(records: dict[str, dict]) -> dict:
    """Per IMU: offset (ms), drift, clock, markers, vector match, quality: the ``setup`` table."""
    out = {}
    for name, r in records.items():
        c = r.get("cluster") or {}
        out[name] = {
            "offset_ms": None if r.get("offset_ns") is None else round(int(r["offset_ns"]) / 1e6, 3),
            "own_offset_ms": None
            if not (r.get("own_clock") or {}).get("offset_ns")
            else round(int(r["own_clock"]["offset_ns"]) / 1e6, 3),
            "drift_ppm": r.get("drift_ppm"),
            "drift_estimated": r.get("drift_estimated"),
            "clock": r.get("clock"),
            **({"clock_of": r["clock_of"]} if r.get("clock_of") else {}),
            "markers": c.get("markers"),
            "pose": c.get("pose"),
            "rejected_markers": c.get("rejected_markers"),
            "vector_match": c.get("vector_match"),
            "frame_alignment": r.get("frame_alignment"),
            "quality": r.get("quality"),
            **({"why": "; ".join(r.get("quality_reasons") or [])} if r.get("quality") == "failed" else {}),
        }
    return out
