"""Independent references shared by the solver tests (not collected: no ``test_`` prefix).

``fista_tv`` is the plain FISTA loop of the conformance kit (:mod:`spslidar.testing.solvers`),
written without the solver classes; the kit's own tests check it against scikit-image and
its optimality conditions (``test_solver_conformance.py``)."""

from spslidar.testing.solvers import fista_tv

__all__ = ["fista_tv"]
