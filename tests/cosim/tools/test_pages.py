"""The result pages and the README's headline table are up to date with results/*.json."""
import json
import shutil
from pathlib import Path

import pytest

from cosim.tools import pages

ROOT = Path(__file__).resolve().parents[3]


def test_committed_pages_match_their_json():
    bad = [str(p.relative_to(ROOT)) for p in pages.stale(ROOT)]
    assert not bad, f"out of date (run `python -m cosim.tools.pages`): {bad}"


def test_every_json_has_a_page_and_the_readme_a_table():
    names = {p.stem for p in (ROOT / "results").glob("*.json")}
    assert names, "no results/*.json"
    for n in names:
        assert (ROOT / "docs" / "results" / f"{n}.md").exists()
    readme = (ROOT / "README.md").read_text()
    block = readme.split(pages.README_BEGIN)[1].split(pages.README_END)[0]
    assert block.count("\n| ") >= 5


def _copy(tmp_path):
    for sub in ("results", "docs/results"):
        shutil.copytree(ROOT / sub, tmp_path / sub)
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    return tmp_path


def test_a_tampered_json_makes_its_page_and_the_readme_stale(tmp_path):
    root = _copy(tmp_path)
    assert pages.stale(root) == []
    f = root / "results" / "tacan_sensitivity.json"
    d = json.loads(f.read_text())
    row = next(r for r in d["snr_sweep"] if r["snr_db"] == 10.0 and r["bearing_deg"] == 90.0)
    row["rmse_deg"] *= 1.5
    f.write_text(json.dumps(d))
    assert set(pages.stale(root)) == {root / "docs" / "results" / "tacan_sensitivity.md",
                                      root / "docs" / "results" / "index.md",
                                      root / "README.md"}
    assert pages.main(["--root", str(root), "--check"]) == 1
    pages.write(root)
    assert pages.stale(root) == []
    assert "1.78 (0.123 deg)" in (root / "README.md").read_text()


def test_a_hand_edited_page_is_stale(tmp_path):
    root = _copy(tmp_path)
    p = root / "docs" / "results" / "monopulse.md"
    p.write_text(p.read_text().replace("| runs | 100 |", "| runs | 101 |"))
    assert pages.stale(root) == [p]


def test_a_page_without_its_json_is_stale_and_removed(tmp_path):
    root = _copy(tmp_path)
    (root / "results" / "ins_hdl.json").unlink()
    orphan = root / "docs" / "results" / "ins_hdl.md"
    assert orphan in pages.stale(root)
    pages.write(root)
    assert not orphan.exists() and pages.stale(root) == []


def test_readme_without_markers_is_refused(tmp_path):
    root = _copy(tmp_path)
    (root / "README.md").write_text("# no markers\n")
    with pytest.raises(ValueError, match="headline:begin"):
        pages.stale(root)


def test_cells():
    assert pages.fmt(None) == "-" and pages.fmt(True) == "yes"
    assert pages.fmt(0.123456) == "0.1235" and pages.fmt(3.0) == "3"
    assert pages.fmt([1, 2]) == "[1, 2]" and pages.fmt(list(range(20))) == "(20 values)"
    assert pages.fmt("a|b") == "a\\|b"
