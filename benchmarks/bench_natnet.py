"""NatNet parse throughput: frames per second of the bridge's decoder.

Decodes a 4-rigid-body FRAMEOFDATA in NatNet 4.1 and 3.0 (the client's fast path, from
the datagram with its header check, and the payload alone), the real Motive 3.0 capture
when it is available, and the full decode of every section for comparison; reports the
median of several runs. Target: >= 20 000 frames/s for the fast path.

    python benchmarks/bench_natnet.py [--frames N] [--runs R]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Callable

from trustfg.bridge import natnet as nn

TARGET_FPS = 20_000
CAPTURE = (Path(__file__).resolve().parent.parent / "tests" / "data" / "natnet-captures"
           / "natnet3_motive2.1_python_natnet" / "mocapframe_packet_v3.bin")


def four_body_frame() -> nn.Frame:
    bodies = tuple(nn.RigidBody(i, (0.4 * i, 0.05, -1.2 + 0.3 * i), (0.0, 0.38, 0.0, 0.92),
                                0.0004, True) for i in range(1, 5))
    return nn.Frame(162734, bodies, 1356.1166, camera_mid_exposure_ticks=1416497730518,
                    camera_data_received_ticks=1416497745808, transmit_ticks=1416497748722)


def rates(fn: Callable[[], object], frames: int, runs: int) -> list[float]:
    out = []
    for _ in range(runs):
        start = time.perf_counter()
        for _ in range(frames):
            fn()
        out.append(frames / (time.perf_counter() - start))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20_000, help="frames per run")
    parser.add_argument("--runs", type=int, default=7, help="runs (the median is reported)")
    args = parser.parse_args(argv)

    frame = four_body_frame()
    cases: list[tuple[str, int, Callable[[], object], bool]] = []
    for version in (nn.V4_1, nn.V3_0):
        packet = nn.serialize(frame, version)
        payload = packet[4:]
        label = f"{version.major}.{version.minor}"
        cases.append((f"NatNet {label}, 4 bodies, datagram -> Frame", len(packet),
                      lambda p=packet, v=version: nn.deserialize(p, v), True))
        cases.append((f"NatNet {label}, 4 bodies, decode_frame(payload)", len(payload),
                      lambda p=payload, v=version: nn.decode_frame(p, v), True))
        cases.append((f"NatNet {label}, 4 bodies, full=True", len(payload),
                      lambda p=payload, v=version: nn.decode_frame(p, v, full=True), False))
        cases.append((f"NatNet {label}, 4 bodies, encode (server side)", len(packet),
                      lambda f=frame, v=version: nn.serialize(f, v), False))
    if CAPTURE.is_file():
        real = CAPTURE.read_bytes()
        cases.append(("Motive 2.1 capture (3.0, 1 body, 11 markers)", len(real),
                      lambda p=real: nn.deserialize(p, nn.V3_0), True))

    print(f"NatNet decode throughput, median of {args.runs} runs x {args.frames} frames "
          f"(target >= {TARGET_FPS} frames/s on the fast path)")
    print(f"{'case':<52} {'bytes':>6} {'frames/s':>10} {'min':>10} {'max':>10}")
    ok = True
    for name, size, fn, gated in cases:
        r = rates(fn, args.frames, args.runs)
        median = statistics.median(r)
        verdict = ""
        if gated:
            ok &= median >= TARGET_FPS
            verdict = "  ok" if median >= TARGET_FPS else "  BELOW TARGET"
        print(f"{name:<52} {size:>6} {median:>10.0f} {min(r):>10.0f} {max(r):>10.0f}{verdict}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
