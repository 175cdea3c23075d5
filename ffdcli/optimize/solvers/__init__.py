"""The flow solvers of ``ffd optimize``: the interface (:mod:`.base`), SU2 (:mod:`.su2`) and the analytic
stand-in for tests (:mod:`.analytic`)."""
