"""``save_property_diagram`` compares the R410A tables with CoolProp and saves a p–h diagram."""

from pymc_vcc.physics.refrigerant.cache import CACHE_ENV
from pymc_vcc.physics.refrigerant.diagram import save_property_diagram


def test_property_diagram_writes_the_diagram_and_prints_the_errors(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    path = save_property_diagram(tmp_path / "demo", n_points=150)
    assert path == tmp_path / "demo" / "refrigerant_R410A.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 50_000
    printed = capsys.readouterr().out
    for name in ("T ", "rho ", "drho_dp", "drho_dh"):
        assert f"  {name}" in printed
    assert "150 random (p, h) states" in printed
