"""The README's MUST/PyMUST table stays true: every function it says sonoflow has is in the
package, every one it says is missing is not, and every public function of PyMUST 0.1.9 is in
the table (a new sonoflow function or a new PyMUST one makes this fail until the table says so)."""
import inspect
import pathlib
import re

import pymust

import sonoflow as sf

README = pathlib.Path(__file__).resolve().parents[3] / "README.md"


def rows():
    text = README.read_text()
    start = text.index("<!-- must-table")
    out = {}
    for line in text[start:].splitlines()[1:]:
        if not line.startswith("|"):
            if out:
                break
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[0] in ("has", "partial", "missing"):
            out[cells[0]] = set(re.findall(r"`([A-Za-z0-9_]+)`", cells[1]))
    return out


def test_readme_must_table_is_true():
    r = rows()
    assert set(r) == {"has", "partial", "missing"}, r.keys()
    for name in r["has"]:
        assert callable(getattr(sf, name, None)), f"README says sonoflow has `{name}`, the package lacks it"
    for name in r["missing"]:
        assert not hasattr(sf, name), f"README says `{name}` is missing, but sonoflow.{name} exists: update the table"
    pm = {n for n in dir(pymust) if not n.startswith("_") and inspect.isfunction(getattr(pymust, n))}
    listed = r["has"] | r["missing"]
    assert pm - listed == set(), f"PyMUST functions not in the README table: {sorted(pm - listed)}"
    extra = {n for n in sf.__all__ if inspect.isfunction(getattr(sf, n)) and n in pm}
    assert extra <= r["has"], f"sonoflow has PyMUST's {sorted(extra - r['has'])}: add to the table's `has` row"
