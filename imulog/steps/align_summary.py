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
        off = r.get("offset_ms")
        own = r.get("own_offset_ms")
        markers = ",".join(r.get("markers") or []) or "no cluster"
        vm = r.get("vector_match")
        rej = r.get("rejected_markers")
        lines.append(
            f"{name}: offset {'-' if off is None else f'{off:.2f} ms'} ({r.get('clock') or '-'} clock"
            f"{'' if own is None else f', own windows {own:.2f} ms'}), {markers}"
            f"{'' if vm is None else f' (vector match {vm:.3f})'}"
            f"{(', dropped ' + ','.join(rej)) if rej else ''}"
            f"{'' if r.get('frame_alignment') else ', no frame alignment'}, quality {r.get('quality')}"
        )
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
