from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REFERENCE_CSV = SHARED / "reference" / "paper_diamond_case_c.csv"


@pytest.fixture
def reference_case_c() -> np.ndarray:
    if not REFERENCE_CSV.exists():
        pytest.skip("../shared/reference is not present")
    return np.loadtxt(REFERENCE_CSV, delimiter=",")


@pytest.fixture(scope="session")
def other_clean():
    """Three clean flights of 600 rows of a planar vehicle unlike the paper's."""
    from identification.experiments.synthetic import OTHER_PLANAR, FlightSpec, planar_flights

    return planar_flights(OTHER_PLANAR, FlightSpec(flights=3, steps=600))
