"""``sonoflow.run`` and ``sonoflow.Recording`` on a real quickstart run (one packet): the report and
evaluation come back as dicts, and every decoded message equals what the PyPI ``mcap`` reader with
``mcap-ros2-support`` decodes from the same file through its ros2msg schemas (an independent
decoder). Needs the ``sonoflow`` executable (SONOFLOW_BIN or PATH; nodes/python/test.sh sets it)."""

import os
import re
import shutil
import sys

import numpy as np
import pytest

import sonoflow as sf

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
HAVE_BIN = bool(os.environ.get("SONOFLOW_BIN") or shutil.which("sonoflow"))
pytestmark = pytest.mark.skipif(not HAVE_BIN, reason="no sonoflow executable (SONOFLOW_BIN)")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("quick") / "run"
    return sf.run(os.path.join(ROOT, "launch", "quickstart.toml"),
                  set={"flow.schedule.n_packets": 1, "doppler.window": [3, 3]}, out=out, echo=False)


def test_run_returns_the_report_and_the_evaluation(quick):
    assert quick["report"]["status"] == "ok"
    assert quick["report"]["graph"] == "quickstart"
    assert os.path.samefile(quick["out"], quick["report"]["out_dir"])
    ev = quick["evaluations"][""]
    assert [p["packet"] for p in ev["packets"]] == [0]
    # the quickstart's regularised x error is documented at ~6-7 % of v_max: far from 0 and 1
    x = ev["packets"][0]["fields"]["regularised"]["x"]["abs_p75"]
    assert 0.001 < x < 0.5
    # the --set reached the node: the resolved launch file says so
    with open(os.path.join(quick["out"], "launch.resolved.toml"), encoding="utf-8") as f:
        text = f.read()
    block = text[text.index("[nodes.doppler.params]"):]
    assert re.search(r"window\s*=\s*\[\s*3\s*,\s*3\s*,?\s*\]", block)


def test_recording_decodes_as_the_pypi_reader_does(quick):
    mcap_reader = pytest.importorskip("mcap.reader")
    decoder = pytest.importorskip("mcap_ros2.decoder")
    rec = sf.Recording(quick["recording"])
    assert rec.complete
    topics = rec.topics()
    assert topics["regularised"] == ("VectorFieldV2", 1)
    assert topics["iq"][0] == "IqFrameV3"
    ours = {(m.topic, m.sequence): m for m in rec.messages(["regularised", "iq", "truth"])}
    theirs = {}
    with open(quick["recording"], "rb") as f:
        r = mcap_reader.make_reader(f, decoder_factories=[decoder.DecoderFactory()])
        for _, channel, msg, dec in r.iter_decoded_messages(topics=["regularised", "iq", "truth"]):
            theirs[(channel.topic, msg.sequence)] = dec
    assert ours.keys() == theirs.keys() and len(ours) == 2 + topics["iq"][1]
    for key, m in ours.items():
        d = theirs[key]
        g = m.header["grid"]
        assert (g["nx"], g["nz"]) == (d.header.grid.nx, d.header.grid.nz)
        if m.type == "IqFrameV3":
            want = np.array([complex(c.re, c.im) for c in d.data], dtype=np.complex64)
            assert m.header["fc"] == d.header.fc and m.header["rx_angle"] == d.header.rx_angle
            assert m.data.size == g["nx"] * g["nz"]
        else:
            want = np.asarray(d.data, dtype=np.float32)
            assert m.header["n_planes"] == d.header.n_planes
            assert m.data.size == m.header["n_planes"] * g["nx"] * g["nz"]
        assert np.array_equal(m.data, want)


def test_recording_filters_by_time_and_names_missing_topics(quick):
    rec = sf.Recording(quick["recording"])
    iq = list(rec.messages("iq"))
    t = sorted(m.log_time for m in iq)
    mid = t[len(t) // 2]
    late = list(rec.messages("iq", start=mid))
    early = list(rec.messages("iq", end=mid))
    assert len(late) + len(early) == len(iq) and early and late
    assert all(m.log_time >= mid for m in late) and all(m.log_time < mid for m in early)
    with pytest.raises(ValueError, match="topics: \\['nope'\\] not in the recording"):
        list(rec.messages("nope"))
    with pytest.raises(OSError):
        sf.Recording(os.path.join(quick["out"], "missing.mcap"))
    with pytest.raises(ValueError, match="not an MCAP file"):
        sf.Recording(os.path.join(quick["out"], "report.json"))


def test_run_reports_bad_input_before_starting(tmp_path):
    with pytest.raises(FileNotFoundError, match="launch_file"):
        sf.run(str(tmp_path / "none.toml"))
    with pytest.raises(RuntimeError, match="no_such_param|unknown"):
        sf.run(os.path.join(ROOT, "launch", "quickstart.toml"), set={"doppler.no_such_param": 1},
               out=tmp_path / "bad", echo=False)
    with pytest.raises(ValueError, match="must be finite"):
        sf.run(os.path.join(ROOT, "launch", "quickstart.toml"), set={"doppler.alias_fraction": float("nan")})


@pytest.mark.parametrize("projection", ["aperture", "nominal"])
def test_python_estimator_swaps_in_and_agrees_with_the_built_in(tmp_path, projection):
    """The example estimator (examples/lag1_estimator.py: sonoflow's lag-1 autocorrelation per
    look, least squares in numpy) as an `exec` node in place of the built-in `doppler` node, with
    the per-pixel aperture projection (`sonoflow.look_projection`, the default) and the nominal
    one: the same vector field to < 1e-5 m/s (both sum in f64 and round to f32, in a different
    order: a few f32 ulps of the 0.77 m/s Nyquist velocity). One packet of 32 frames × 2 looks in
    (64 I/Q frames), 2 maps + 1 vector field out."""
    text = open(os.path.join(ROOT, "launch", "quickstart.toml"), encoding="utf-8").read()
    example = os.path.join(ROOT, "nodes", "python", "examples", "lag1_estimator.py")
    text += (f'\n[nodes.doppler.variants.python]\nexec = {sys.executable!r}\nargs = [{example!r}]\n'
             'ports = { iq = "IqFrameV3", vector = "VectorFieldV2", maps = "DopplerMapV2" }\n')
    launch = tmp_path / "quickstart-python.toml"
    launch.write_text(text.replace("'", '"'), encoding="utf-8")
    common = {"flow.schedule.n_packets": 1, "flow.density_per_mm2": 4.0, "doppler.projection": projection}
    runs = {}
    for name, swap in (("builtin", None), ("python", {"doppler": "python"})):
        res = sf.run(str(launch), set=common, swap=swap, out=tmp_path / name, echo=False)
        rec = sf.Recording(res["recording"])
        runs[name] = (list(rec.messages("vector")), len(list(rec.messages("maps"))), res)
    (vb,), maps_b, _ = runs["builtin"]
    (vp,), maps_p, res_p = runs["python"]
    doppler = [nd for nd in res_p["report"]["nodes"] if nd["name"] == "doppler"][0]
    assert doppler["program"] == sys.executable and doppler["ok"]
    assert doppler["stats"]["messages_in"] == 64 and doppler["stats"]["messages_out"] == 3
    assert (maps_b, maps_p) == (2, 2)
    assert vb.header["grid"] == vp.header["grid"] and vb.header["packet"] == vp.header["packet"]
    assert list(vb.header["plane_ids"][:4]) == list(vp.header["plane_ids"][:4])
    g = vb.header["grid"]
    n = g["nx"] * g["nz"]
    b, p = vb.data.reshape(-1, n), vp.data.reshape(-1, n)
    assert np.array_equal(b[2], p[2]), "flags differ"
    est = b[2] == 0
    assert est.sum() > n / 2
    assert np.max(np.abs(b[:2, est] - p[:2, est])) < 1e-5


def test_run_live_adds_the_viewer_and_checks_its_address(tmp_path):
    # A live view on a free port with nobody watching: the run is unchanged and the live node's
    # statistics are in the report; a bad address or type is refused before anything starts.
    r = sf.run(os.path.join(ROOT, "launch", "quickstart.toml"), set={"flow.schedule.n_packets": 1},
               out=tmp_path / "live", echo=False, live="127.0.0.1:0")
    assert r["report"]["status"] == "ok"
    assert "live" in [n["name"] for n in r["report"]["nodes"]]
    with pytest.raises(TypeError, match="live"):
        sf.run(os.path.join(ROOT, "launch", "quickstart.toml"), live=8765)
    with pytest.raises(RuntimeError, match="--live"):
        sf.run(os.path.join(ROOT, "launch", "quickstart.toml"), live="nowhere:port", out=tmp_path / "bad",
               echo=False)
