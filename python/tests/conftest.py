import pytest

import arfi


@pytest.fixture(scope="session")
def sim() -> arfi.Simulation:
    """The default scenario, built once (one HAS march)."""
    return arfi.Simulation()


@pytest.fixture(scope="session")
def ideal(sim: arfi.Simulation):
    return sim.arfi_image()


def pytest_terminal_summary(terminalreporter) -> None:
    """How many generated bad inputs the property tests tried (README, Reliability)."""
    import sys

    fuzz = sys.modules.get("test_fuzz") or sys.modules.get("python.tests.test_fuzz")
    if fuzz is not None and fuzz.TRIED:
        total = sum(fuzz.TRIED.values())
        parts = ", ".join(f"{k} {v}" for k, v in fuzz.TRIED.items())
        terminalreporter.write_line(f"generated inputs tried: {total} ({parts})")
