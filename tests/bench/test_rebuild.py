"""``python -m bench.rebuild``: the catalogue covers reports/, a rebuild reproduces the committed tables
byte for byte, and a rerun carries a finished run into a folder whole or not at all."""

from __future__ import annotations

import gzip
import shutil
import sys
from pathlib import Path

import pytest

from bench import rebuild as rb

ROOT = Path(__file__).resolve().parents[2]
REPORTS = ROOT / "reports"


def test_catalogue_names_every_committed_report_folder():
    folders = {p.relative_to(REPORTS).as_posix() for p in REPORTS.iterdir() if p.is_dir()}
    folders |= {p.relative_to(REPORTS).as_posix() for p in (REPORTS / "heldout").iterdir() if p.is_dir()}
    listed = set(rb.BY_FOLDER)
    missing = {f for f in folders if f not in listed and not any(f.startswith(e + "/") for e in listed)}
    missing.discard("heldout")  # only a parent of its two reports
    assert not missing, f"report folders without a catalogue entry: {sorted(missing)}"
    for entry in rb.CATALOGUE:
        if entry.kind != "derived":
            assert (REPORTS / entry.folder).is_dir(), entry.folder
    # every sweep's command is one this suite has, and names its output folder
    for entry in rb.CATALOGUE:
        if entry.kind in ("sweep", "timing", "dataset"):
            argv = entry.argv(Path("OUT"), "W")
            assert argv[0] == "-m" and argv[1].startswith("bench.") and "OUT" in argv, entry.folder


def test_rebuild_reproduces_the_committed_tables(tmp_path):
    name = "heldout/fast-motion"
    copy = tmp_path / "reports" / name
    shutil.copytree(REPORTS / name, copy, ignore=shutil.ignore_patterns("figures", "images", "report.pdf"))
    assert rb.main(["--only", name, "--reports", str(tmp_path / "reports")]) == 0
    committed = sorted(p.relative_to(REPORTS / name / "tables") for p in (REPORTS / name / "tables").iterdir())
    assert committed == sorted(p.relative_to(copy / "tables") for p in (copy / "tables").iterdir())
    for rel in committed:
        assert (copy / "tables" / rel).read_bytes() == (REPORTS / name / "tables" / rel).read_bytes(), rel
    assert (copy / "report.pdf").is_file()


def _fake_entry(script: str) -> rb.Entry:
    return rb.Entry("fake", "a test folder", "sweep", ("-c", script, "{out}"))


WRITES_A_RUN = (
    "import sys, pathlib; out = pathlib.Path(sys.argv[1]); (out / 'tables').mkdir(parents=True);"
    "(out / 'results.csv').write_text('method,value\\nnew,2\\n');"
    "(out / 'config.json').write_text('{\"run\": \"new\"}'); (out / 'tables' / 'summary.md').write_text('new')"
)


def _committed(tmp_path: Path) -> Path:
    folder = tmp_path / "reports" / "fake"
    (folder / "tables").mkdir(parents=True)
    (folder / "README.md").write_text("notes")
    (folder / "config.json").write_text('{"run": "old"}')
    (folder / "tables" / "summary.md").write_text("old")
    (folder / "tables" / "stale.md").write_text("a table the new run does not write")
    with gzip.open(folder / "results.csv.gz", "wt") as f:
        f.write("method,value\nold,1\n")
    return folder


def test_rerun_carries_a_finished_run_whole(tmp_path):
    folder = _committed(tmp_path)
    rb.rerun(_fake_entry(WRITES_A_RUN), tmp_path / "reports", "unused", tmp_path / "work")
    assert (folder / "README.md").read_text() == "notes"  # the folder's own notes stay
    assert (folder / "config.json").read_text() == '{"run": "new"}'
    assert (folder / "tables" / "summary.md").read_text() == "new"
    assert not (folder / "tables" / "stale.md").exists()  # nothing of the old run is mixed in
    with gzip.open(folder / "results.csv.gz", "rt") as f:
        assert f.read() == "method,value\nnew,2\n"
    assert sorted(p.name for p in folder.parent.iterdir()) == ["fake"]  # no staging left behind


def test_a_rerun_keeps_subfolders_of_notes_whole_even_where_their_files_share_a_runs_names(tmp_path):
    """Table 2 on other CPU kinds lives in subfolders (timing/milan/timing.csv, its metadata.json): the run
    replaces the folder's own config and tables, not those."""
    folder = _committed(tmp_path)
    (folder / "milan").mkdir()
    (folder / "milan" / "config.json").write_text('{"machine": "milan"}')
    (folder / "milan" / "timing.csv").write_text("method,ms\nsnm,130\n")
    (folder / "loaded.md").write_text("per-frame time beside another job")
    rb.rerun(_fake_entry(WRITES_A_RUN), tmp_path / "reports", "unused", tmp_path / "work")
    assert (folder / "config.json").read_text() == '{"run": "new"}'
    assert (folder / "milan" / "config.json").read_text() == '{"machine": "milan"}'
    assert (folder / "milan" / "timing.csv").read_text() == "method,ms\nsnm,130\n"
    assert (folder / "loaded.md").read_text() == "per-frame time beside another job"


def test_a_failed_rerun_leaves_the_committed_folder_as_it_was(tmp_path):
    folder = _committed(tmp_path)
    before = {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    fails = WRITES_A_RUN + "; sys.exit(3)"
    with pytest.raises(rb.RebuildError, match="exited with 3.*unchanged"):
        rb.rerun(_fake_entry(fails), tmp_path / "reports", "unused", tmp_path / "work")
    after = {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    assert after == before


def test_bad_names_and_derived_reruns_are_refused(capsys):
    assert rb.main(["--only", "lihgt"]) == 2
    assert "unknown ['lihgt']" in capsys.readouterr().err
    assert rb.main(["--rerun", "margins.md"]) == 2
    assert "nothing to rerun" in capsys.readouterr().err
    assert rb.main(["--rerun", "light", "--weights", str(ROOT / "no-such-folder")]) == 2
    assert "not a folder" in capsys.readouterr().err


def test_list_prints_every_entry_with_its_command(capsys):
    assert rb.main(["--list"]) == 0
    out = capsys.readouterr().out
    for entry in rb.CATALOGUE:
        assert entry.folder in out
    assert "python -m bench.sweep --axis light-noise --full" in out
    assert sys.executable not in out


def test_margins_of_a_folder_without_results_is_one_line(tmp_path, capsys):
    from bench.reporting import margins

    assert margins.main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "results.csv" in err


def test_a_rerun_keeps_the_figures_its_folder_holds_and_refreshes_those_it_draws_again(tmp_path):
    """A dataset's contact sheets are committed and need the run's images: a rerun must not drop them."""
    folder = _committed(tmp_path)
    (folder / "figures").mkdir()
    (folder / "figures" / "sheet_a.png").write_bytes(b"old a")
    (folder / "figures" / "sheet_b.png").write_bytes(b"old b")
    draws_a = WRITES_A_RUN + "; (out / 'figures').mkdir(); (out / 'figures' / 'sheet_a.png').write_bytes(b'new a')"
    rb.rerun(_fake_entry(draws_a), tmp_path / "reports", "unused", tmp_path / "work")
    assert (folder / "figures" / "sheet_a.png").read_bytes() == b"new a"
    assert (folder / "figures" / "sheet_b.png").read_bytes() == b"old b"
