"""The page at `/` in a real headless browser (Debian's chromium): it loads the maps and draws
a device's pose after an update, and shows nothing without a token where tokens are needed."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile

import pytest
from conftest import T_TRUE, view

from semloc.client import Client
from semloc.serve.access import Access

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="chromium is not installed (Debian package chromium; .ci/run installs it)",
)
TOKEN = "page-reader-token"


def rendered(url: str) -> str:
    """The page's DOM after its scripts ran (headless, no network but loopback)."""
    with tempfile.TemporaryDirectory() as profile:
        done = subprocess.run(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking", "--disable-component-update",
             "--disable-sync", f"--user-data-dir={profile}", "--virtual-time-budget=5000",
             "--dump-dom", url],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    assert done.returncode == 0, done.stderr[-400:]
    return done.stdout


def test_the_page_shows_maps_versions_and_a_live_pose(serve, building, tmp_path):
    tokens = tmp_path / "tokens.json"
    tokens.write_text(json.dumps({"tokens": [
        {"token": TOKEN, "maps": {"office": ["read"]}},
        {"token": "device-token-1", "maps": {"*": ["read", "localize", "write"]}},
    ]}))  # fmt: skip
    server = serve(access=Access.from_file(tokens))
    device = Client(server.url, "device-token-1")
    device.put_map("office", building)
    device.put_map("lab", building)
    local = view(building, [3, 4, 5, 6, 7, 8, 9], T_TRUE)
    session = device.session("office", up=local.up.tolist())
    assert session.update(list(local), stamp=3.0)["status"] == "localized"

    page = rendered(f"{server.url}/#token={TOKEN}")
    assert 'data-ready="yes"' in page
    assert re.findall(r'<li data-map="([^"]+)"', page) == ["office"]  # lab is not this token's
    assert page.count('class="object"') == len(building)
    # another token's session: shown with its pose, never with its id (a capability)
    arrow = re.search(r'<polygon class="device localized" data-session="device 1" '
                      r'points="([^"]+)"', page)  # fmt: skip
    assert arrow is not None and session.session_id not in page
    tip = [float(v) for v in arrow.group(1).split()[0].split(",")]
    heading = T_TRUE[:2, 0]
    expected = T_TRUE[:2, 3] + 0.5 * heading / (heading**2).sum() ** 0.5
    assert abs(tip[0] - expected[0]) < 0.01 and abs(-tip[1] - expected[1]) < 0.01
    assert "v1" in page and "upload" in page

    locked = rendered(f"{server.url}/")
    assert 'data-ready="error"' in locked and "401" in locked and 'class="object"' not in locked
