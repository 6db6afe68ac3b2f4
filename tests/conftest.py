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
