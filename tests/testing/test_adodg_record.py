"""benchmarks/adodg/record.py: a run's small files kept in the repository and put back."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from benchmarks.adodg import record
from benchmarks.adodg.su2_side import su2_bin, su2_env


def _ffd_run(root):
    (root / "evals" / "0001").mkdir(parents=True)
    (root / "evals" / "0002").mkdir(parents=True)
    (root / "history.csv").write_text("evaluation,objective\n1,0.5\n2,0.4\n")
    (root / "best.yaml").write_text("changes: []\n")
    for k in ("0001", "0002"):
        (root / "evals" / k / "result.json").write_text(json.dumps({"index": int(k)}))
        (root / "evals" / k / "history.csv").write_text("rms[Rho]\n-10.1\n")
        (root / "evals" / k / "mesh.su2").write_text("NDIME= 3\n" * 10)     # not a record file
    return root


def _su2_run(root):
    dsn = root / "DESIGNS" / "DSN_001"
    (dsn / "DIRECT").mkdir(parents=True)
    (dsn / "ADJOINT_DRAG").mkdir()
    (root / "config.cfg").write_text("CONV_RESIDUAL_MINVAL= -10\n")
    (root / "project.pkl").write_bytes(b"\x80\x04pickle")
    (root / "history_project.csv").write_text('"DRAG","LIFT"\n0.0077,0.375\n')
    (root / "mesh_ffd.su2").write_text("big mesh\n")                      # project mesh: not a record file
    (dsn / "config_DSN.cfg").write_text("DV_VALUE= 0\n")
    (dsn / "design.pkl").write_bytes(b"\x80\x04design")
    (dsn / "DIRECT" / "history_direct.csv").write_text('"rms[Rho]"\n-10.2\n')
    (dsn / "DIRECT" / "restart_flow.dat").write_text("solution\n" * 100)  # a placeholder on restore
    (dsn / "ADJOINT_DRAG" / "of_grad.csv").write_text('"VARIABLE","GRADIENT"\n0,1e-3\n')
    return root


def test_ffd_run_kept_and_restored_byte_for_byte(tmp_path):
    run = _ffd_run(tmp_path / "run")
    out = record.keep(run, tmp_path / "rec")
    assert out.kind == "ffd"
    assert set(out.files) == {"history.csv", "best.yaml", "evals/0001/result.json", "evals/0002/result.json",
                              "evals/0001/history.csv", "evals/0002/history.csv"}
    back = tmp_path / "back"
    assert record.restore(tmp_path / "rec", back).written == 6
    for rel in out.files:
        assert (back / rel).read_bytes() == (run / rel).read_bytes()
    assert not (back / "evals" / "0001" / "mesh.su2").exists()
    assert record.restore(tmp_path / "rec", back).written == 0   # nothing the run has is replaced


def test_su2_run_restored_with_placeholders(tmp_path, monkeypatch):
    monkeypatch.setattr(record, "slim_project", lambda folder: None)     # not SU2's pickle: nothing to slim
    run = _su2_run(tmp_path / "run")
    out = record.keep(run, tmp_path / "rec")
    assert out.kind == "su2"
    assert "project.pkl" in out.files and "DESIGNS/DSN_001/ADJOINT_DRAG/of_grad.csv" in out.files
    assert "mesh_ffd.su2" not in out.files
    meta = json.loads((tmp_path / "rec" / "record.json").read_text())
    assert meta["placeholders"] == ["DESIGNS/DSN_001/DIRECT/restart_flow.dat"]
    back = tmp_path / "back"
    record.restore(tmp_path / "rec", back, drop=False)            # not SU2's pickle: nothing to drop
    assert (back / "DESIGNS/DSN_001/DIRECT/restart_flow.dat").stat().st_size == 0
    with pytest.raises(record.RecordError, match="project.pkl"):
        record.restore(tmp_path / "rec", tmp_path / "again")
    assert (back / "project.pkl").read_bytes() == b"\x80\x04pickle"


def test_too_large_left_out_and_said(tmp_path, monkeypatch):
    run = _ffd_run(tmp_path / "run")
    monkeypatch.setattr(record, "MAX_BYTES", 20)
    (run / "history.csv").write_text("x" * 21)
    out = record.keep(run, tmp_path / "rec")
    assert "history.csv" in out.too_large and "history.csv" not in out.files
    assert json.loads((tmp_path / "rec" / "record.json").read_text())["too_large"] == ["history.csv"]


def test_errors_exit_2_and_name_the_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert record.main(["keep", str(tmp_path / "empty"), "x"]) == 2
    assert "empty" in capsys.readouterr().err
    assert record.main(["keep", str(tmp_path / "missing"), "x"]) == 2
    with pytest.raises(record.RecordError, match="record.json"):
        record.restore(tmp_path / "nothing", tmp_path / "run")


def _su2_missing() -> str | None:
    try:
        su2_bin()
    except RuntimeError as e:
        return str(e)
    return None


CUT_LAST = """
import os, SU2
p = SU2.io.load_data("project.pkl")
d = p.designs[-1]
d.state.GRADIENTS.pop("LIFT", None)
os.makedirs(os.path.join(d.folder, "ADJOINT_LIFT"), exist_ok=True)
SU2.io.save_data("project.pkl", p)
print(len(p.designs))
"""


@pytest.mark.skipif(_su2_missing() is not None, reason=str(_su2_missing()))
def test_su2_design_cut_short_is_dropped_on_restore(tmp_path):
    """On a real record of SU2's run (Case 3, H0): a last design whose LIFT adjoint had begun but not
    finished is taken out of project.pkl with its folder; a finished one is kept."""
    rec = record.RECORDS / "case3_h0_su2_wall_distance"
    run = tmp_path / "run"
    record.restore(rec, run)
    n = len(list((run / "DESIGNS").glob("DSN_*")))
    assert record.drop_unfinished(run) is None                    # already finished: nothing to drop
    out = subprocess.run([sys.executable, "-c", CUT_LAST], cwd=run, env=su2_env(), capture_output=True, text=True,
                         check=True)
    assert int(out.stdout) == n
    dropped = record.drop_unfinished(run)
    assert dropped == f"DESIGNS/DSN_{n:03d}"
    assert not (run / dropped).exists() and len(list((run / "DESIGNS").glob("DSN_*"))) == n - 1


def test_a_file_changing_while_copied_is_copied_again(tmp_path, monkeypatch):
    src, dst = tmp_path / "a", tmp_path / "b"
    src.write_text("one")
    calls = []
    real = record.shutil.copyfile

    def copy_then_touch(a, b):
        real(a, b)
        calls.append(1)
        if len(calls) == 1:                        # the run rewrites the file during the first copy
            src.write_text("two, longer")

    monkeypatch.setattr(record.shutil, "copyfile", copy_then_touch)
    assert record.steady_copy(src, dst)
    assert len(calls) == 2 and dst.read_text() == "two, longer"

    def always_touch(a, b):
        real(a, b)
        src.write_text(src.read_text() + "x")       # a solve still writing its history

    monkeypatch.setattr(record.shutil, "copyfile", always_touch)
    assert not record.steady_copy(src, dst) and not dst.exists()


def test_large_files_packed_and_unpacked_and_a_keep_replaces_the_record(tmp_path, monkeypatch):
    run = _ffd_run(tmp_path / "run")
    monkeypatch.setattr(record, "PACK_ABOVE", 100)
    big = "evaluation,objective\n" + "".join(f"{k},0.5\n" for k in range(500))
    (run / "history.csv").write_text(big)
    record.keep(run, tmp_path / "rec")
    assert (tmp_path / "rec" / "history.csv.gz").is_file() and not (tmp_path / "rec" / "history.csv").exists()
    first = (tmp_path / "rec" / "history.csv.gz").read_bytes()
    record.keep(run, tmp_path / "rec")                              # the same bytes give the same file
    assert (tmp_path / "rec" / "history.csv.gz").read_bytes() == first
    record.restore(tmp_path / "rec", tmp_path / "back")
    assert (tmp_path / "back" / "history.csv").read_text() == big
    shutil.rmtree(run / "evals" / "0002")                           # the run lost an evaluation: so does the record
    record.keep(run, tmp_path / "rec")
    assert not (tmp_path / "rec" / "evals" / "0002").exists()
    assert not (tmp_path / "rec.new").exists()


@pytest.mark.skipif(_su2_missing() is not None, reason=str(_su2_missing()))
def test_su2_design_folder_unknown_to_the_project_is_removed(tmp_path):
    run = tmp_path / "run"
    record.restore(record.RECORDS / "case3_h0_su2_wall_distance", run)
    n = len(list((run / "DESIGNS").glob("DSN_*")))
    extra = run / "DESIGNS" / f"DSN_{n + 1:03d}"
    (extra / "DIRECT").mkdir(parents=True)
    (extra / "config_DSN.cfg").write_text("begun after project.pkl was saved\n")
    assert record.drop_unfinished(run) == f"DESIGNS/DSN_{n + 1:03d}"
    assert not extra.exists()


def test_status_counts_designs_and_solves(tmp_path, monkeypatch):
    monkeypatch.setattr(record, "slim_project", lambda folder: None)
    run = _ffd_run(tmp_path / "ffd")
    for k in ("0001", "0002"):
        (run / "evals" / k / "result.json").write_text(json.dumps({"solves": {"flow": 1, "adjoint": 2}}))
    record.keep(run, tmp_path / "rec_ffd")
    assert "2 evaluations, 2 flow + 4 adjoint solves, finished" in record.status(tmp_path / "rec_ffd")
    record.keep(_su2_run(tmp_path / "su2"), tmp_path / "rec_su2")
    assert "1 designs, 1 flow + 1 adjoint solves, not finished" in record.status(tmp_path / "rec_su2")


def test_a_keep_that_fails_leaves_nothing_half_written(tmp_path, monkeypatch):
    run = _su2_run(tmp_path / "run")

    def no_su2(folder):
        raise record.RecordError("SU2 not found")

    monkeypatch.setattr(record, "slim_project", no_su2)
    with pytest.raises(record.RecordError, match="SU2 not found"):
        record.keep(run, tmp_path / "rec")
    assert not (tmp_path / "rec").exists() and not (tmp_path / "rec.new").exists()
