"""Car-link codec throughput: encode, decode and the receiver filter, per datagram.

    python benchmarks/bench_carlink.py [--count N]

At 50 Hz per car the link needs microseconds per second; this is a regression guard
and a number to compare with a firmware implementation, not a bottleneck.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Callable

from trustfg.bridge.carlink import Command, CommandFilter, Flags, decode_command, encode_command


@dataclass(frozen=True)
class BenchConfig:
    count: int = 100_000


def _per_call_us(fn: Callable[[int], object], count: int) -> float:
    started = time.perf_counter()
    for i in range(count):
        fn(i)
    return (time.perf_counter() - started) / count * 1e6


def run(config: BenchConfig) -> dict[str, float]:
    """Microseconds per call of each stage."""
    commands = [Command(3, i, 0.02 * i, 0.25, -0.5, Flags.NONE) for i in range(1024)]
    datagrams = [encode_command(c) for c in commands]
    stream = [encode_command(Command(3, i, 0.02 * i, 0.25, -0.5)) for i in range(config.count)]
    f = CommandFilter(3)
    return {
        "construct Command": _per_call_us(lambda i: Command(3, i, 0.5, 0.25, -0.5), config.count),
        "encode_command": _per_call_us(lambda i: encode_command(commands[i & 1023]), config.count),
        "decode_command": _per_call_us(lambda i: decode_command(datagrams[i & 1023]), config.count),
        "CommandFilter.accept": _per_call_us(lambda i: f.accept(stream[i], 0.02 * i), config.count),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=BenchConfig.count, help="calls per stage")
    args = parser.parse_args(argv)
    for name, us in run(BenchConfig(count=args.count)).items():
        print(f"{name:24s} {us:7.2f} us/call  {1e6 / us:12,.0f} /s")


if __name__ == "__main__":
    main()
