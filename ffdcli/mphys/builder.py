"""``FFDBuilder``: an MPhys ``Builder`` whose mesh-coordinate subsystem is ffd's geometry component, so that
``ScenarioAerodynamic(..., geometry_builder=FFDBuilder(...), in_MultipointParallel=True)`` (and the
aerostructural and aerothermal scenarios) wire it in without hand connections: its coordinate inputs and
outputs carry MPhys 2.0's names (``x_aero0_geometry_input`` / ``_output``, ``x_struct0_...``,
``x_thermal0_...``) and the ``mphys_coordinates`` tag the scenario promotes by."""

from __future__ import annotations

from mphys import Builder

from ffdcli.mphys.geometry import FFDGeometry
from ffdcli.mphys.names import coordinate_names


class FFDBuilder(Builder):
    """Builds one :class:`~ffdcli.mphys.geometry.FFDGeometry` per scenario (or one for a hand-wired run script).

    Parameters
    ----------
    design : str
        The design file (its mesh: the solver's grid or any mesh of the wing).
    disciplines : sequence
        The disciplines the geometry moves: ``("aero",)``, ``("aero", "struct")``, or MPhys geometry classes.
    dvs : dict, optional
        ``{input name: ffd variable names or prefixes}`` (``{"twist": "c0.twist"}``).
    design_vars : bool
        Every change item of the design file as an input (``c0_twist`` ...), when ``dvs`` is not given.
    **options
        Any other option of :class:`~ffdcli.mphys.geometry.FFDGeometry` (``overrides``, ``work_dir``, ``cache_dir``).
    """

    def __init__(self, design, disciplines=("aero",), dvs=None, design_vars=None, **options):
        super().__init__()
        for d in disciplines:
            coordinate_names(d)                   # an unknown discipline: said now, not at setup
        self.design = str(design)
        self.disciplines = tuple(disciplines)
        self.dvs = dict(dvs or {})
        self.design_vars = (not self.dvs) if design_vars is None else bool(design_vars)
        self.component_options = dict(options)
        self.comm = None

    def initialize(self, comm):
        """Keep the communicator (the component takes its own from OpenMDAO)."""
        self.comm = comm

    def get_mesh_coordinate_subsystem(self, scenario_name=None):
        """A new geometry component: the disciplines' coordinates in and out, the design variables as inputs."""
        return FFDGeometry(design=self.design, disciplines=self.disciplines, dvs=self.dvs,
                           design_vars=self.design_vars, **self.component_options)

    def get_ndof(self):
        """Three coordinates a node."""
        return 3
