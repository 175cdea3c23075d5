"""``ffd optimize``: a gradient-based shape optimisation with a flow solver and its adjoint.

- :mod:`ffdcli.optimize.solvers`: the solver interface (``base``), SU2 (``su2``) and the analytic
  stand-in for tests (``analytic``);
- :mod:`ffdcli.optimize.store`: one folder per evaluation, the cache and ``--resume``;
- :mod:`ffdcli.optimize.problem`: one design evaluated (ffd's geometry, the solver, the chain rule);
- :mod:`ffdcli.optimize.driver`: scipy's SLSQP / trust-constr on scaled variables and constraints;
- :mod:`ffdcli.optimize.check`: ``--check-gradient``;
- :mod:`ffdcli.optimize.history`, :mod:`ffdcli.optimize.best`: what a run leaves behind;
- :mod:`ffdcli.optimize.workflow`: :func:`run_optimize`, the whole command as one call.
"""
