"""The paper's own method, run through pysindy as the authors did.

``ps.SINDy`` with the paper's 26-term library, forward finite differences (order 1) and SR3
with an L1 regulariser; lambda = 0.45 in the paper. pysindy 2.x's SR3 takes a regulariser
weight where 1.x took a threshold: we convert with ``SR3.calculate_l0_weight(lambda, nu)``
(lambda^2 / 2 nu), iterate to convergence and refit the support by least squares (a 1.x
default). On the authors' case C file this gives their published coefficients to the printed
digits (0.993, -5.549, -9.811, 5.556, 4000); the 0.993 term comes out as cos(phi) phi_dot,
which the library also holds and which equals phi_dot to 0.5 % at these roll angles. The
fitted pysindy model is converted to an :class:`IdentifiedModel` through its feature names.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pysindy as ps
from sklearn.exceptions import ConvergenceWarning

from identification.data import Trajectory
from identification.fit import TALLY
from identification.libraries import paper_planar_library
from identification.model import IdentifiedModel

PAPER_LAMBDA = 0.45


def from_pysindy(model: ps.SINDy, system: str | None = None, **meta: object) -> IdentifiedModel:
    """Converts a fitted ``ps.SINDy`` with control into an :class:`IdentifiedModel`."""
    names = list(model.feature_names)
    n_states = model.coefficients().shape[0]
    state_names, input_names = tuple(names[:n_states]), tuple(names[n_states:])
    return IdentifiedModel(
        list(model.get_feature_names()),
        np.asarray(model.coefficients()),
        state_names,
        input_names,
        system,
        dict(meta),
    )


def fit_paper(
    trajs: Sequence[Trajectory], lam: float = PAPER_LAMBDA, max_iter: int = 1000
) -> IdentifiedModel:
    """The paper's pipeline on planar trajectories (forward difference + SR3-L1)."""
    if not trajs:
        raise ValueError("no trajectories to fit")
    first = trajs[0]
    model = ps.SINDy(
        optimizer=ps.SR3(
            reg_weight_lam=ps.SR3.calculate_l0_weight(lam, 1.0),
            regularizer="L1",
            relax_coeff_nu=1.0,
            max_iter=max_iter,
            unbias=True,
        ),
        feature_library=paper_planar_library(include_duplicate=True),
        differentiation_method=ps.FiniteDifference(order=1),
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        model.fit(
            [tr.x for tr in trajs],
            t=[tr.t for tr in trajs],
            u=[tr.u for tr in trajs],
            feature_names=[*first.state_names, *first.input_names],
        )
    TALLY.add([w for w in caught if issubclass(w.category, ConvergenceWarning)])
    return from_pysindy(
        model, "planar", method="paper (forward difference + SR3-L1)", optimizer="sr3-l1",
        **{"lambda": lam, "dt": first.dt, "n_samples": int(sum(len(t) for t in trajs))},
    )  # fmt: skip
