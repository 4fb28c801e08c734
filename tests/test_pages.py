"""Report pages in a real browser (issue 64): headless Chromium loads a fit's page and the demo's
front page; every image decodes (naturalWidth > 0) and every link resolves to a file. Skips
without Debian's ``chromium``."""
import json
import re
import shutil
import subprocess
from urllib.parse import unquote

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium (apt-get install chromium)")

PROBE = ("<script>window.addEventListener('load', () => {const bad = [...document.images].filter("
         "i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute('src'));"
         "document.body.setAttribute('data-images', document.images.length);"
         "document.body.setAttribute('data-broken', bad.join('|'));});</script></body>")


def browser_check(page):
    """(images on the page, the ones Chromium could not decode, links to no file) for an HTML
    file, loaded headless with a probe script that counts its decoded images."""
    probe = page.with_name("_probe_" + page.name)
    probe.write_text(page.read_text().replace("</body>", PROBE))
    try:
        out = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
                              "--virtual-time-budget=10000", "--dump-dom", probe.as_uri()],
                             capture_output=True, text=True, timeout=180).stdout
    finally:
        probe.unlink()
    images = int(re.search(r'data-images="(\d+)"', out).group(1))
    broken = [s for s in re.search(r'data-broken="([^"]*)"', out).group(1).split("|") if s]
    hrefs = re.findall(r'href="([^"#]+)"', page.read_text())
    dead = [h for h in hrefs if not (page.parent / unquote(h)).exists()]
    return images, broken, dead


def test_a_fit_page_and_the_demo_page_load_whole_in_chromium(tmp_path):
    import trimesh
    from invface.report.demo import write_demo_index
    from invface.report.fit import write_report
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    fit = tmp_path / "demo" / "fit-smile"
    for kind in ("blendshape", "simulation"):
        d = fit / kind
        d.mkdir(parents=True)
        d.joinpath("fit.json").write_text(json.dumps({"kind": kind, "weights": {"mouthSmileLeft": 0.5},
                                                      "status": "curves: cost", "history": [{"cost": 2.0},
                                                                                           {"cost": 1.0}]}))
        np.savez(d / "fit.npz", surface=s.vertices, neutral=s.vertices, triangles=s.faces,
                 vertex_error=np.linspace(0, 1e-3, len(s.vertices)))
    pages = [write_report(fit)]
    shutil.copy(fit / "blendshape" / "mesh_error.png", fit / "blendshape" / "wipe.png")
    pages.append(write_demo_index(tmp_path / "demo"))
    for page in pages:
        images, broken, dead = browser_check(page)
        assert images >= 1 and broken == [] and dead == [], (page, images, broken, dead)
