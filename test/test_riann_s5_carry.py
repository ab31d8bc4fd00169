"""riann_ros/estimators/riann/s5_carry.py: the network attitude carried to the stamps, and the gyro increments (the
plain-float form against the vectorised reference, on random blocks)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from riann_ros.estimators.riann.s5_carry import Carry
from riann_ros.estimators.riann.stage import SMALL_BLOCK, BiasBlock, CarryIn, GridBlock, NetworkBlock
from riann_ros.rotations import normalized


def _block(n: int, seed: int) -> CarryIn:
    """``n`` samples over random rows (some samples make none), network attitudes, gyro, steps and biases."""
    rng = np.random.default_rng(seed)
    m = n + 3
    net = np.array([normalized(tuple(q)) for q in rng.normal(size=(m, 4))])
    r1 = np.sort(rng.integers(0, m, n))
    r1[0] = max(r1[0], 1)
    r0 = np.concatenate([[0], r1[:-1]])
    vec = [tuple(v) for v in rng.normal(size=(n, 3)).tolist()]
    s = rng.uniform(0.0, 0.01, n)
    s[::4] = 0.0
    g = GridBlock([], [], [], r0.tolist(), r1.tolist(), vec, s.tolist(), vec[::-1], s[::-1].tolist(), [])
    bias = [tuple(v) for v in (0.01 * rng.normal(size=(m + 1, 3))).tolist()]
    return CarryIn(g, BiasBlock([], bias, [0.0] * (m + 1)), NetworkBlock(net, np.zeros(m)))


def _samples(block: CarryIn, a: int, b: int) -> CarryIn:
    """Samples ``a:b`` of the block (the rows as they are)."""
    g = block.grid
    return block._replace(grid=g._replace(r0=g.r0[a:b], r1=g.r1[a:b], gyr_delta_rad_s=g.gyr_delta_rad_s[a:b],
                                          delta_s=g.delta_s[a:b], gyr_carry_rad_s=g.gyr_carry_rad_s[a:b],
                                          carry_s=g.carry_s[a:b]))


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 3 * SMALL_BLOCK))
def test_the_plain_float_form_equals_the_vectorised_reference(seed, n):
    block = _block(n, seed)
    fl, vec = Carry()._floats(block), Carry()._vector(block)
    assert np.abs(np.array(fl.q) - np.array(vec.q)).max() < 1e-12
    assert np.abs(np.array(fl.delta) - np.array(vec.delta)).max() < 1e-12


def test_a_block_equals_its_samples_one_at_a_time():
    """The newest network output carries over from block to block (samples without rows of their own)."""
    block = _block(40, 1)
    whole = Carry().run(block)
    one = Carry()
    for k in range(40):
        part = one.run(_samples(block, k, k + 1))
        assert np.allclose(part.q[0], whole.q[k], atol=1e-12) and np.allclose(part.delta[0], whole.delta[k], atol=1e-12)
