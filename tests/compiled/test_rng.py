"""NumPy's random streams inside kernels: the same numbers as the Generator, from NumPy's own tables."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
from numba import njit

from estimator.compiled import rng as compiled_rng
from estimator.compiled.rng import ZIGGURAT_TABLES

# sha256 of NumPy's normal-ziggurat tables as numba.np.random._constants ships them
# (numba 0.68 / NumPy 2.4; unchanged in NumPy since 1.17).
ZIGGURAT_SHA256 = "fc41458680e7ff6d3e883626b69822713c4bd6130a7ec785457fea0464921376"
UPGRADE_HELP = (
    "numba.np.random._constants changed (a Numba or NumPy upgrade?). The kernels' normals are "
    "no longer guaranteed to be Generator.standard_normal's: compare the new tables with NumPy's "
    "numpy/random/src/distributions/ziggurat_constants.h and, if NumPy changed its algorithm, "
    "bump every env's -vN (tests/coop_gym/test_recorded_trajectories.py will fail too)."
)


def _tables_digest() -> str:
    digest = hashlib.sha256()
    for name in ("ki_double", "wi_double", "fi_double"):
        table = np.ascontiguousarray(ZIGGURAT_TABLES[name])
        digest.update(table.dtype.str.encode())
        digest.update(table.tobytes())
    digest.update(np.array([ZIGGURAT_TABLES["ziggurat_nor_r"], ZIGGURAT_TABLES["ziggurat_nor_inv_r"]]).tobytes())
    return digest.hexdigest()


def test_ziggurat_tables_are_the_known_ones() -> None:
    assert _tables_digest() == ZIGGURAT_SHA256, UPGRADE_HELP


def test_ziggurat_tables_match_an_independent_derivation() -> None:
    """Marsaglia & Tsang's 256-layer construction for the normal, in NumPy's table layout.

    Layer edges x_255 = r > x_254 > ... > x_1 with equal areas v: x_{k-1} = f^-1(v / x_k + f(x_k)),
    x_0 = v / f(r) (the base strip); wi = x / 2^52, fi = f(x) (fi_0 = f(0) = 1),
    ki_k = 2^52 x_{k-1} / x_k (ki_0 = 2^52 r / x_0, ki_1 = 0).
    """
    r, v = 3.6541528853610088, 0.00492867323399

    def f(x: float) -> float:
        return math.exp(-0.5 * x * x)

    x = np.zeros(256)
    x[255] = r
    for k in range(254, 0, -1):
        x[k] = math.sqrt(-2.0 * math.log(v / x[k + 1] + f(x[k + 1])))
    x[0] = v / f(r)
    scale = 2.0**52
    fi = np.array([1.0, *(f(t) for t in x[1:])])
    ki = scale * np.array([r / x[0], 0.0, *(x[k - 1] / x[k] for k in range(2, 256))])
    assert ZIGGURAT_TABLES["wi_double"].dtype == np.float64, UPGRADE_HELP
    assert ZIGGURAT_TABLES["ki_double"].dtype == np.uint64, UPGRADE_HELP
    assert ZIGGURAT_TABLES["wi_double"] == pytest.approx(x / scale, rel=1e-8), UPGRADE_HELP
    assert ZIGGURAT_TABLES["fi_double"] == pytest.approx(fi, rel=1e-8), UPGRADE_HELP
    assert ZIGGURAT_TABLES["ki_double"].astype(np.float64) == pytest.approx(ki, rel=1e-8), UPGRADE_HELP
    assert ZIGGURAT_TABLES["ziggurat_nor_r"] == r, UPGRADE_HELP
    assert ZIGGURAT_TABLES["ziggurat_nor_inv_r"] == 1.0 / r, UPGRADE_HELP


@njit(cache=False)
def _normals(g: np.ndarray, out: np.ndarray) -> None:
    for k in range(out.shape[0]):
        out[k] = compiled_rng.standard_normal(g)


def test_standard_normal_is_the_generators_over_many_draws_including_the_tail() -> None:
    n = 2_000_000
    expected = np.random.Generator(np.random.PCG64(7)).standard_normal(n)
    got = np.empty(n)
    rng = np.random.Generator(np.random.PCG64(7))  # alive while the kernel draws from its state
    _normals(compiled_rng.bit_generator_row(rng), got)
    mismatch = np.flatnonzero(got != expected)
    assert mismatch.size == 0, f"{UPGRADE_HELP} First differing draw: {mismatch[:1]}"
    # Every branch ran: the tail beyond r (about 1 draw in 3,800) and the wedges.
    assert np.count_nonzero(np.abs(expected) > ZIGGURAT_TABLES["ziggurat_nor_r"]) > 300


@pytest.mark.parametrize("bit_generator", [np.random.PCG64, np.random.MT19937, np.random.Philox, np.random.SFC64])
def test_compiled_draws_are_the_generators_own_numbers(bit_generator: type) -> None:
    """The kernels' normals, uniforms and bounded integers equal the Generator methods'."""

    @njit(cache=False)
    def draw(g: np.ndarray, highs: np.ndarray, out: np.ndarray) -> None:
        k = 0
        for high in highs:
            out[k] = compiled_rng.integers(g, high)
            out[k + 1] = compiled_rng.random(g)
            for j in range(2, 7):
                out[k + j] = compiled_rng.standard_normal(g)
            k += 7

    highs = np.tile(np.arange(1, 11), 300)
    reference = np.random.Generator(bit_generator(2024))
    expected = np.empty(7 * highs.size)
    for r, high in enumerate(highs):
        expected[7 * r] = reference.integers(high)
        expected[7 * r + 1] = reference.random()
        expected[7 * r + 2 : 7 * r + 7] = reference.standard_normal(5)
    rng = np.random.Generator(bit_generator(2024))
    got = np.empty_like(expected)
    draw(compiled_rng.bit_generator_row(rng), highs, got)
    assert np.array_equal(got, expected)
    # The Generator object itself advanced: Python draws continue the same stream.
    assert rng.standard_normal(3).tolist() == reference.standard_normal(3).tolist()
    assert np.abs(expected).max() > 3.7  # the ziggurat's tail branch was exercised


def test_bit_generator_row_rejects_other_random_sources() -> None:
    with pytest.raises(TypeError, match=r"numpy\.random\.Generator"):
        compiled_rng.bit_generator_row(np.random.RandomState(0))  # type: ignore[arg-type]
