"""Soak (and overload) run: the four tracker nodes as separate processes over DDS, the camera
offering a looping synthetic sequence at --rate Hz for --minutes; per window of --window
seconds the JointStates per second and the latency p50/p95/max (a lean subscriber in its own
process: arrival minus the camera frame's header stamp), and each node's anonymous memory
(RssAnon from /proc/PID/status; the lookup's memory-mapped database is file-backed, not
anonymous), and the stages' own processing times (segmentation and lookup times carried in
HandPoseCandidates, the IK time in the tracking status; no image is received here). Prints a
table per window and the growth per node; --json writes the same."""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.tools._cli import add_pipeline_arguments, run_tool, tool_parser

__all__ = ['rss_anon_mb', 'main']

NODE_NAMES = ('camera', 'segmentation', 'lookup', 'ik')


def rss_anon_mb(pid: int) -> float:
    """Anonymous resident memory of process ``pid`` in MB (NaN if it is gone)."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('RssAnon:'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


class _StageTimes:
    """Collects the stages' processing times with the time they arrived (no images)."""

    def __init__(self) -> None:
        from colorglove_msgs.msg import HandPoseCandidates
        from std_msgs.msg import String

        from colorglove_ros.ros.background_node import BackgroundNode
        from colorglove_ros.ros.pipeline_run import ik_times_ms

        self.rows: list[tuple[float, str, float]] = []      # (time, stage, ms)
        self.listener = BackgroundNode('soak_stage_times')

        def on_candidates(msg: HandPoseCandidates) -> None:
            now = time.time()
            if msg.observation.processing_time_ms > 0:
                self.rows.append((now, 'segmentation', msg.observation.processing_time_ms))
            if msg.lookup_time_ms > 0:
                self.rows.append((now, 'lookup', msg.lookup_time_ms))

        def on_status(msg: String) -> None:
            self.rows.extend((time.time(), 'ik', ms) for ms in ik_times_ms([msg.data]))

        node = self.listener.node
        node.create_subscription(HandPoseCandidates, '/hand/pose_candidates', on_candidates, 50)
        node.create_subscription(String, '/hand/tracking_status', on_status, 50)
        self.listener.start()

    def p95_ms(self, stage: str, start: float, end: float) -> float:
        """95th percentile of ``stage``'s times that arrived in [start, end)."""
        values = [ms for t, name, ms in list(self.rows) if name == stage and start <= t < end]
        return float(np.percentile(values, 95)) if values else float('nan')

    def close(self) -> None:
        """Stop listening."""
        self.listener.close()


def _soak(args) -> int:
    from colorglove_ros.ros.latency_probe import LatencyProbe, ProbeRecord, window_summaries
    from colorglove_ros.ros.pipeline_run import looping_pipeline

    memory_rows: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory() as folder:
        launcher, _ = looping_pipeline(args.database, args.seed, args.frames, args.rate,
                                       Path(folder))
        probe = LatencyProbe()
        stages = None
        record = None
        # everything started inside the try: a SIGTERM (SystemExit, see run_tool) landing
        # between two starts must still stop what already runs
        try:
            probe.start()
            stages = _StageTimes()
            launcher.start()
            if not probe.wait_for_first(args.startup_timeout):
                print(f'[soak] no JointState within {args.startup_timeout:g} s of start-up',
                      flush=True)
                return 1
            print(f'[soak] tracking; warming up {args.warmup:g} s, then {args.minutes:g} min '
                  f'at {args.rate:g} Hz offered', flush=True)
            time.sleep(args.warmup)
            measure_start_ns = time.time_ns()
            windows = max(1, int(round(args.minutes * 60.0 / args.window)))
            for k in range(windows + 1):
                if k:
                    time.sleep(max(0.0, measure_start_ns * 1e-9 + k * args.window - time.time()))
                row = {'t_s': k * args.window}
                for name, process in zip(NODE_NAMES, launcher.processes, strict=True):
                    alive = process is not None and process.poll() is None
                    row[f'{name}_rss_anon_mb'] = (rss_anon_mb(process.pid) if alive
                                                  else float('nan'))
                memory_rows.append(row)
            exited = [name for name, p in zip(NODE_NAMES, launcher.processes, strict=True)
                      if p is None or p.poll() is not None]
            record = probe.stop()
        finally:
            try:
                launcher.stop()
            finally:
                if record is None:
                    probe.close()
                if stages is not None:
                    stages.close()
    keep = record.arrival_ns >= measure_start_ns
    measured = ProbeRecord(record.stamp_ns[keep], record.arrival_ns[keep])
    rows = window_summaries(measured, args.window)[:windows]
    window_origin = measured.arrival_ns[0] * 1e-9 if len(measured.arrival_ns) else 0.0
    for row in rows:
        start = window_origin + row['window_start_s']
        for stage in ('segmentation', 'lookup', 'ik'):
            row[f'{stage}_p95_ms'] = stages.p95_ms(stage, start, start + args.window)
        memory = min(memory_rows, key=lambda m: abs(m['t_s'] - row['window_start_s']))
        row.update({k: v for k, v in memory.items() if k != 't_s'})
    print_table(rows, title=f'soak: {args.rate:g} Hz offered, windows of {args.window:g} s')
    latency_ms = measured.latencies_s * 1e3
    summary = {
        'offered_hz': args.rate, 'minutes': args.minutes, 'window_s': args.window,
        'joint_states': int(len(latency_ms)), 'rate_hz': measured.rate_hz,
        'first_arrival_s': ((measured.arrival_ns[0] - measure_start_ns) * 1e-9
                            if len(latency_ms) else np.nan),
        'last_arrival_s': ((measured.arrival_ns[-1] - measure_start_ns) * 1e-9
                           if len(latency_ms) else np.nan),
        'latency_p50_ms': float(np.percentile(latency_ms, 50)) if len(latency_ms) else np.nan,
        'latency_p95_ms': float(np.percentile(latency_ms, 95)) if len(latency_ms) else np.nan,
        'window_p95_ms_first': rows[0]['latency_p95_ms'] if rows else np.nan,
        'window_p95_ms_last': rows[-1]['latency_p95_ms'] if rows else np.nan,
        'nodes_exited': ','.join(exited) or 'none',
        'frame_period_ms': 1e3 / args.rate,
    }
    end = window_origin + len(rows) * args.window
    processing = 0.0
    for stage in ('segmentation', 'lookup', 'ik'):
        summary[f'{stage}_p95_ms'] = stages.p95_ms(stage, window_origin, end)
        processing += summary[f'{stage}_p95_ms']
    # the overload bound of issue 16: three frame periods plus the pipeline's own processing
    summary['bound_3_periods_plus_processing_ms'] = 3e3 / args.rate + processing
    for name in NODE_NAMES:
        first, last = memory_rows[0][f'{name}_rss_anon_mb'], memory_rows[-1][f'{name}_rss_anon_mb']
        summary[f'{name}_rss_anon_growth_mb'] = last - first
    print_table([{'figure': k, 'value': v} for k, v in summary.items()], title='soak summary')
    if args.json:
        write_json(args.json, {'summary': summary, 'windows': rows, 'memory': memory_rows})
    return 0 if not exited and len(latency_ms) else 1


def main(argv: list[str] | None = None) -> int:
    """``colorglove_soak [--minutes M] [--rate HZ] [--window S] [--json PATH]``."""
    parser = tool_parser(__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0, help='measured duration')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate offered, Hz')
    parser.add_argument('--window', type=float, default=60.0, help='window length, seconds')
    parser.add_argument('--warmup', type=float, default=10.0,
                        help='seconds after the first JointState before measuring')
    parser.add_argument('--startup-timeout', type=float, default=180.0,
                        help='longest wait for the first JointState, seconds')
    add_pipeline_arguments(parser, frames=300, seed=1, sequence='looping synthetic sequence')
    args = parser.parse_args(argv)
    if args.minutes <= 0 or args.rate <= 0 or args.window <= 0:
        parser.error('--minutes, --rate and --window must be > 0')
    return run_tool('colorglove_soak', lambda: _soak(args))


if __name__ == '__main__':
    sys.exit(main())
