"""``benchmarks/triage_backend.py`` (crash triage, one child process per case) on the test
backend: a working case reports its image mean next to Mitsuba's, and a case whose child
fails is reported with its message instead of ending the triage."""


import pbr
from scripts import load_script


def _triage():
    return load_script("benchmarks/triage_backend.py")


def test_triage_reports_results_and_failures():
    t = _triage()
    ok = t.main(["--backend", pbr.get_backend(), "--cases", "direct", "--res", "8", "--spp", "64"])
    assert len(ok) == 1 and ok[0]["status"] == "ok", ok
    assert ok[0]["variant"] == f"{pbr.get_backend()}_ad_spectral"
    assert abs(ok[0]["mean"] / ok[0]["mitsuba_mean"] - 1) < 0.1
    bad = t.main(["--backend", pbr.get_backend(), "--cases", "path", "--res", "8", "--spp", "4",
                  "--flags", "NoSuchFlag"])
    assert [r["status"] for r in bad] == ["ok", "error"]
    assert "NoSuchFlag" in bad[1]["message"]
