"""``eval covariance``: NEES of real matches against the truth, split along and across the weakest
direction."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import IcpParams, PlIcpParams, match
from mbicp_viz.core.events import IterationEvent, PairStatus
from mbicp_viz.evaluation.covariance import chi2_mean_bounds, nees

from .conftest import DATA


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.floats(-1, 1), min_size=3, max_size=3),
    st.lists(st.floats(-1, 1), min_size=3, max_size=3),
    st.floats(0.5, 5.0),
)
def test_nees_splits_into_along_and_across_when_the_direction_is_an_axis_of_the_covariance(e, v, L):
    """With Sigma's eigenvectors along the weakest direction and across it, the 3-dof NEES is the
    sum of its 1-dof and 2-dof parts; a sample drawn from Sigma has NEES ~ chi2(3) (mean 3)."""
    v = np.array(v)
    if np.linalg.norm(v) < 0.1:
        v = np.array([1.0, 0.0, 0.0])
    v /= np.linalg.norm(v)
    U = np.linalg.svd(np.eye(3) - np.outer(v, v))[0][:, :2]
    S_scaled = 0.3 * np.outer(v, v) + 2.0 * U @ U.T  # in (x, y, L theta)
    D_inv = np.diag([1.0, 1.0, 1.0 / L])
    cov = D_inv @ S_scaled @ D_inv  # back in (x, y, theta)
    n = nees(np.array(e), cov, v, L)
    assert np.isclose(n.total, n.along + n.across, rtol=1e-9, atol=1e-12)
    rng = np.random.default_rng(0)
    draws = rng.multivariate_normal(np.zeros(3), cov, 4000)
    mean = np.mean([nees(d, cov, v, L).total for d in draws])
    lo, hi = chi2_mean_bounds(3, 4000, 0.999)
    assert lo <= mean <= hi


def test_eval_covariance_on_real_pairs(tmp_path):
    png = tmp_path / "nees.png"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "covariance",
            str(DATA / "intel-relations.log"),
            "--algos",
            "plicp,psm",
            "--workers",
            "1",
            "--png",
            str(png),
        ],
    )
    assert res.exit_code == 0, res.output
    out = res.stdout
    assert "plicp:" in out and "pairs right" in out and "chi2(3) 95 % bounds for the mean" in out
    assert "along the weakest direction" in out and "scale the covariance by" in out
    assert "psm: no covariance reported" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "params", [IcpParams(restart=False), PlIcpParams(restart=False)], ids=["icp", "plicp"]
)
def test_csm_covariance_is_sigma2_A_inverse_of_the_last_pairs_seen_from_the_result(
    params, intel, laserazos
):
    """ICP's and PL-ICP's covariance, recomputed here from the pairs of the last iteration's event:
    A = sum J^T C J at the points moved by the result (C: I for ICP, n n^T of the segment for
    PL-ICP), the error the mean squared distance to the segments' feet, sigma^2 A^-1."""
    for log in (intel, laserazos):
        for i in range(5):
            events = []
            result = match(
                log.scan(i),
                log.scan(i + 1),
                log.scan(i).pose.inverse() @ log.scan(i + 1).pose,
                params,
                events.append,
            )
            start, last = events[0], [e for e in events if isinstance(e, IterationEvent)][-1]
            kept = last.pairs.status == PairStatus.KEPT
            moved = result.pose.apply(start.obj_points[last.pairs.obj_index[kept]])
            a, b = (start.ref_points[last.pairs.ref_index[kept, k]] for k in (0, 1))
            e = b - a
            t = np.clip(np.einsum("ij,ij->i", moved - a, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
            err = np.mean(np.sum((moved - (a + t[:, None] * e)) ** 2, axis=1))
            n = np.column_stack((e[:, 1], -e[:, 0])) / np.linalg.norm(e, axis=1)[:, None]
            line = isinstance(params, PlIcpParams)
            C = (
                np.einsum("ki,kj->kij", n, n)
                if line
                else np.broadcast_to(np.eye(2), (len(n), 2, 2))
            )
            J = np.zeros((len(moved), 2, 3))
            J[:, 0, 0] = J[:, 1, 1] = 1.0
            J[:, 0, 2], J[:, 1, 2] = -moved[:, 1], moved[:, 0]
            A = np.einsum("kji,kjl,klm->im", J, C, J)
            K = len(moved)
            assert result.pairs_kept == K and np.isclose(result.error, err, rtol=1e-9)
            np.testing.assert_allclose(
                result.covariance, err * K / (2 * K - 3) * np.linalg.inv(A), rtol=1e-6
            )
