"""examples/one_liar.py: in the lab scene the honest cars trust the paper's liar well
below each other, keep the widest distance from it, and still all arrive."""

import re

import pytest

from tests.examples.conftest import png

pytestmark = pytest.mark.realtime

END = re.compile(r"car (\d) at the end: trust in the liar ([\d.]+), in honest peers ([\d.]+); "
                 r"epsilon from the liar ([\d.]+) m")


def test_honest_cars_trust_the_liar_less_and_keep_further_from_it(run_example, tmp_path):
    out = run_example("one_liar", "--liar", "1")
    ends = END.findall(out)
    assert [car for car, *_ in ends] == ["2", "3", "4"], out
    for car, in_liar, in_honest, epsilon in ends:
        assert float(in_liar) < float(in_honest) - 0.2  # the detection gap of docs/design/trust.md
        assert float(in_honest) > 0.8  # no honest car distrusts an honest peer
        assert float(epsilon) > 0.8  # near the widest epsilon, 2 eps_0 = 0.9 m
    told_apart = re.search(r"told apart .* at: (-?[\d.]+) s", out)
    assert told_apart is not None and float(told_apart[1]) < 10.0, out
    assert "arrived: [True, True, True, True]" in out
    assert png(tmp_path / "one_liar.png")
