"""The derivative chain as small stages with one protocol (:class:`~ffdcli.chain.stage.Stage`:
``forward``, ``jvp``, ``vjp``, values arriving on every call), and :class:`~ffdcli.chain.chain.DesignChain`
composing them: values -> lattices -> surface; lattices -> frames; surface and frames -> volume;
volume -> quality. The chain owns the MPI reductions (:class:`~ffdcli.chain.share.MeshShare`)."""

from ffdcli.chain.cache import Memo, Once, digest
from ffdcli.chain.chain import DesignChain
from ffdcli.chain.frames import FrameStage, derivative_basis
from ffdcli.chain.lattices import LatticeStage
from ffdcli.chain.quality import QualityStage
from ffdcli.chain.share import MeshShare
from ffdcli.chain.stage import Stage
from ffdcli.chain.surface import SurfaceStage
from ffdcli.chain.volume import VolumeStage

__all__ = ["DesignChain", "FrameStage", "LatticeStage", "Memo", "MeshShare", "Once", "QualityStage", "Stage",
           "SurfaceStage", "VolumeStage", "derivative_basis", "digest"]
