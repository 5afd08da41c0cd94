"""A readable text timeline of a fault schedule (``roft-sim faults show``).

Two parts: a strip with one column per camera frame (what each frame carries), then, per
detection stream, one line per network run: capture frame -> arrival frame(s), delay, fate and
the injected faults. Example (``paper`` preset, first frames)::

    frame       0         10        20
                |         |         |
    camera      ......................
    pose run    C.....C.....C.....C...
    pose arrive 1.....1.....1.....1...

Strip legend: camera ``.`` delivered, ``X`` dropped, ``d`` depth fault, ``f`` flow fault, ``b``
both; run ``C`` run delivered, ``o`` delivered with an injected outlier or corruption, ``x``
dropped by a fault, ``m`` detector miss, ``s`` superseded by a stale result, ``>`` arrives after
the end, ``.`` no run; arrive: number of deliveries at that frame (``+`` for more than 9).
"""

from __future__ import annotations

from roft_sim.faults.events import DeliveryEvent, DetectionRecord, StreamName
from roft_sim.faults.schedule import DetectionSchedule

__all__ = ["format_timeline", "STRIP_LEGEND"]

STRIP_LEGEND = (
    "legend: camera  . delivered  X dropped  d depth fault  f flow fault  b both\n"
    "        run     C delivered  o outlier/corrupted  x dropped  m detector miss"
    "  s superseded  > after end  . no run\n"
    "        arrive  deliveries at that frame (+ for more than 9)"
)

_RUN_MARK = {"dropped": "x", "missed": "m", "superseded": "s", "after_end": ">"}


def _run_mark(record: DetectionRecord) -> str:
    if record.fate == "delivered":
        return "o" if record.corruptions else "C"
    return _RUN_MARK[record.fate]


def _strip_rows(schedule: DetectionSchedule) -> list[tuple[str, str]]:
    n = schedule.n_frames
    cam = schedule.camera
    camera = []
    for k in range(n):
        if cam.dropped[k]:
            camera.append("X")
        else:
            d, f = bool(cam.depth[k]), bool(cam.flow[k])
            camera.append("b" if d and f else "d" if d else "f" if f else ".")
    rows = [("camera", "".join(camera))]
    for stream in ("pose", "mask"):
        runs = ["."] * n
        for r in schedule.records(stream):
            runs[r.true_capture_k] = _run_mark(r)
        counts = [0] * n
        for e in schedule.deliveries(stream):
            counts[e.arrival_k] += 1
        arrive = "".join("." if c == 0 else str(c) if c <= 9 else "+" for c in counts)
        rows += [(f"{stream} run", "".join(runs)), (f"{stream} arrive", arrive)]
    return rows


def _format_strip(schedule: DetectionSchedule, width: int) -> list[str]:
    rows = _strip_rows(schedule)
    label_w = max(len(name) for name, _ in rows) + 1
    lines = []
    for start in range(0, max(schedule.n_frames, 1), width):
        stop = min(start + width, schedule.n_frames)
        ticks = range(start - start % 10 + (10 if start % 10 else 0), stop, 10)
        numbers = [" "] * (stop - start + 6)
        bars = [" "] * (stop - start)
        for t in ticks:
            text = str(t)
            numbers[t - start : t - start + len(text)] = text
            bars[t - start] = "|"
        lines.append(f"{'frame':<{label_w}}{''.join(numbers).rstrip()}")
        lines.append(f"{'':<{label_w}}{''.join(bars).rstrip()}")
        lines += [f"{name:<{label_w}}{row[start:stop]}" for name, row in rows]
        lines.append("")
    return lines


def _out_of_order(events: tuple[DeliveryEvent, ...]) -> set[tuple[int, int]]:
    """(detection_id, arrival_k) of deliveries that come after a later-captured result."""
    latest = -1
    out = set()
    for e in events:
        if e.true_capture_k < latest and e.copy == "original":
            out.add((e.detection_id, e.arrival_k))
        latest = max(latest, e.true_capture_k)
    return out


def _stream_table(schedule: DetectionSchedule, stream: StreamName) -> list[str]:
    records = schedule.records(stream)
    events = schedule.deliveries(stream)
    ms = 1000.0 / schedule.fps
    late = _out_of_order(events)
    fates: dict[str, int] = {}
    for r in records:
        fates[r.fate] = fates.get(r.fate, 0) + 1
    delays = [e.delay_frames for e in events]
    head = f"{stream}: {len(records)} network runs, {len(events)} deliveries"
    head += "; " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in sorted(fates.items()))
    if delays:
        head += (
            f"; delay {min(delays)}..{max(delays)} frames (mean {sum(delays) / len(delays):.2f},"
            f" {min(delays) * ms:.0f}..{max(delays) * ms:.0f} ms)"
        )
    lines = [head]
    if not records:
        return lines
    lines.append(
        f"  {'id':>4} {'capture':>7} {'reported':>8}  {'arrival(s)':<16} {'delay':>6}  note"
    )
    by_id: dict[int, list[DeliveryEvent]] = {}
    for e in events:
        by_id.setdefault(e.detection_id, []).append(e)
    for r in records:
        deliveries = by_id.get(r.detection_id, [])
        arrivals = ", ".join(
            str(e.arrival_k) + ("" if e.copy == "original" else f"({e.copy[:3]})")
            for e in deliveries
        )
        first = next((e for e in deliveries if e.copy != "stale"), None)
        delay = f"+{first.delay_frames}" if first is not None else "-"
        notes = []
        if r.fate == "missed":
            notes.append("detector miss")
        elif r.fate == "dropped":
            notes.append(f"DROPPED by {r.cause}")
        elif r.fate == "superseded":
            notes.append(f"SUPERSEDED by a stale result ({r.cause})")
        elif r.fate == "after_end":
            notes.append("arrives after the end")
        if r.reported_capture_k != r.true_capture_k:
            notes.append(f"TIME STAMP {r.reported_capture_k - r.true_capture_k:+d}")
        if r.is_outlier:
            notes.append("OUTLIER")
        if r.corruptions:
            notes.append(" ".join(c.describe() for c in r.corruptions))
        for e in deliveries:
            if (e.detection_id, e.arrival_k) in late:
                notes.append("OUT OF ORDER")
                break
        if any(e.copy == "duplicate" for e in deliveries):
            notes.append("DUPLICATED")
        if any(e.copy == "stale" for e in deliveries):
            notes.append("RE-DELIVERED STALE")
        lines.append(
            f"  {r.detection_id:>4} {r.true_capture_k:>7} {r.reported_capture_k:>8}  "
            f"{arrivals or '-':<16} {delay:>6}  {'; '.join(notes)}".rstrip()
        )
    return lines


def format_timeline(
    schedule: DetectionSchedule, *, header: tuple[str, ...] = (), width: int = 60
) -> str:
    """The schedule as text: header lines, the per-frame strip (``width`` frames per block) and
    one line per network run of each detection stream (capture -> arrival, fate, faults)."""
    n, fps = schedule.n_frames, schedule.fps
    lines = list(header)
    lines.append(f"{n} camera frames at {fps} fps ({1000.0 / fps:.1f} ms per frame)")
    cam = schedule.camera
    lines.append(
        f"camera: {int(cam.dropped.sum())} dropped, {sum(bool(c) for c in cam.depth)} with depth "
        f"faults, {sum(bool(c) for c in cam.flow)} with flow faults"
    )
    lines.append("")
    lines += _format_strip(schedule, max(width, 10))
    lines.append(STRIP_LEGEND)
    for stream in ("pose", "mask"):
        lines.append("")
        lines += _stream_table(schedule, stream)
    dropped_frames = [k for k in range(n) if cam.dropped[k]]
    if dropped_frames:
        lines.append("")
        lines.append("dropped camera frames: " + ", ".join(map(str, dropped_frames)))
    return "\n".join(lines) + "\n"
