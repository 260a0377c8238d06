"""The nine-parameter model and the sphere residual (paper 1 eq. 1, 5-7)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from calib_jax.models.accel import (
    AccelParams,
    alpha_matrix,
    correct,
    distort,
    normalized_sphere_residual,
    sphere_residual,
)
from calib_jax.simulate import random_directions, random_params

seeds = st.integers(0, 2**31 - 1)


@given(seeds)
def test_correct_inverts_distort(seed):
    p = jnp.asarray(random_params(seed, scale=1.0))
    a = jnp.asarray(random_directions(50, seed))
    np.testing.assert_allclose(correct(p, distort(p, a)), a, atol=1e-12)


@given(seeds, st.sampled_from([1.0, 9.80665, 9.81744, 4096.0]))
def test_zero_residual_at_truth_in_any_unit(seed, g):
    # raw = alpha a + beta with |a| = g: eq. 6 is exactly zero at the true parameters
    p = jnp.asarray(random_params(seed, scale=g))
    a = g * jnp.asarray(random_directions(30, seed))
    raw = distort(p, a)
    e = sphere_residual(p, raw, g)
    assert float(jnp.max(jnp.abs(e))) < 1e-10 * g * g
    assert float(jnp.max(jnp.abs(normalized_sphere_residual(p, raw, g)))) < 1e-10


def test_residual_matches_paper_formula(rng):
    # independent evaluation of e = |g|^2 - (a'-b)' (alpha^-1)^2 (a'-b) with numpy
    p = random_params(3)
    raw = rng.normal(size=(20, 3))
    A = np.array(alpha_matrix(jnp.asarray(p)))
    Ai2 = np.linalg.inv(A) @ np.linalg.inv(A)
    d = raw - p[6:9]
    expected = 1.3**2 - np.einsum("ni,ij,nj->n", d, Ai2, d)
    np.testing.assert_allclose(
        sphere_residual(jnp.asarray(p), jnp.asarray(raw), 1.3), expected, rtol=1e-12
    )


def test_alpha_is_symmetric_in_paper_order():
    p = jnp.arange(1.0, 10.0)
    A = alpha_matrix(p)
    np.testing.assert_array_equal(A, A.T)
    assert A[0, 1] == 4.0 and A[0, 2] == 5.0 and A[1, 2] == 6.0  # S_xy, S_xz, S_yz
    np.testing.assert_array_equal(AccelParams.from_vector(p).to_vector(), p)


def test_jacobian_matches_finite_differences(rng, tol):
    p = jnp.asarray(random_params(11))
    raw = jnp.asarray(rng.normal(size=(40, 3)))
    J = jax.jacfwd(normalized_sphere_residual)(p, raw, 1.0)
    h = 1e-6
    fd = np.stack(
        [
            (
                normalized_sphere_residual(p.at[j].add(h), raw, 1.0)
                - normalized_sphere_residual(p.at[j].add(-h), raw, 1.0)
            )
            / (2 * h)
            for j in range(9)
        ],
        axis=1,
    )
    np.testing.assert_allclose(J, fd, atol=tol.FD_ABS)
    np.testing.assert_allclose(J, jax.jacrev(normalized_sphere_residual)(p, raw, 1.0), atol=1e-12)


def test_correct_is_jittable_vmappable_differentiable():
    p = jnp.asarray(random_params(2))
    raw = jnp.asarray(random_directions(8, 2)) + 0.1
    out = jax.jit(jax.vmap(correct, in_axes=(None, 0)))(p, raw)
    np.testing.assert_allclose(out, correct(p, raw), atol=1e-14)
    g = jax.grad(lambda q: jnp.sum(correct(q, raw) ** 2))(p)
    assert np.all(np.isfinite(g))
    # gradient with respect to the data too (pipelines differentiate through the samples)
    gx = jax.grad(lambda x: jnp.sum(correct(p, x)))(raw)
    assert gx.shape == raw.shape and np.all(np.isfinite(gx))


def test_singular_alpha_gives_nonfinite_not_exception():
    p = jnp.zeros(9)
    out = correct(p, jnp.ones((2, 3)))
    assert not np.all(np.isfinite(out))


@pytest.mark.parametrize("g", [1.0, 9.80665])
def test_residual_units(g):
    p = jnp.asarray(random_params(5, scale=g))
    raw = distort(p, g * jnp.asarray(random_directions(5, 5))) * 1.01
    e = sphere_residual(p, raw, g)
    np.testing.assert_allclose(e / g**2, normalized_sphere_residual(p, raw, g), rtol=1e-12)
