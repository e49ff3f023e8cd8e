import pytest

import arfi


@pytest.fixture(scope="session")
def sim() -> arfi.Simulation:
    """The default scenario, built once (one HAS march)."""
    return arfi.Simulation()


@pytest.fixture(scope="session")
def ideal(sim: arfi.Simulation):
    return sim.arfi_image()
