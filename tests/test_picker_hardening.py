"""`flexreg pick`'s web app under hostile or careless requests: a deeply nested JSON body, an
oversized body (declared or chunked), a state change from another origin; and Save writing its
files at once, complete, even inside the command line's all-or-nothing block."""

# ruff: noqa: F401, F811 - the picker tests' `session` and `client` fixtures, imported below, are
# this file's too: test arguments of those names are the fixtures, not redefinitions

from __future__ import annotations

import asyncio
import json
import logging
import warnings

import pytest
from test_picker import (  # the picker tests' scene and fixtures
    TOKEN,
    _h,
    client,
    session,
    true_clicks,
)

from flexreg.calibration import read_correspondences
from flexreg.errors import InputError
from flexreg.io.files import all_or_nothing

pytest.importorskip("starlette")
pytest.importorskip("httpx")

with warnings.catch_warnings():  # recent Starlette releases prefer httpx2 for the test client
    warnings.simplefilter("ignore", Warning)
    from starlette.testclient import TestClient

from flexreg.picker import create_app
from flexreg.picker.server import MAX_BODY_BYTES

BASE = "http://127.0.0.1:8765"


def _call(app, method: str, headers: dict[str, str], chunks: list[bytes]) -> tuple[int, dict, int]:
    """Drive the ASGI app directly with a body streamed in ``chunks`` (``more_body`` set on
    all but the last): (status, JSON answer, number of chunks the app read)."""
    read = 0
    sent: list[dict] = []

    async def receive() -> dict:
        nonlocal read
        if read >= len(chunks):
            return {"type": "http.disconnect"}
        read += 1
        return {"type": "http.request", "body": chunks[read - 1], "more_body": read < len(chunks)}

    async def send(message: dict) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": method,
        "scheme": "http",
        "path": "/api/pairs",
        "raw_path": b"/api/pairs",
        "query_string": b"",
        "root_path": "",
        "headers": [(k.lower().encode(), v.encode()) for k, v in headers.items()],
        "client": ("127.0.0.1", 50000),
        "server": ("127.0.0.1", 8765),
    }
    asyncio.run(app(scope, receive, send))
    start = next(m for m in sent if m["type"] == "http.response.start")
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return start["status"], json.loads(body), read


# ------------------------------------------------------------------------------ nested JSON


def test_deeply_nested_json_is_a_400_without_a_traceback(client, caplog):
    depth = 100_000
    with caplog.at_level(logging.DEBUG):
        r = client.post("/api/pairs", content=b"[" * depth + b"]" * depth, headers=_h())
        r2 = client.post("/api/pairs", content=b'{"a":' * depth + b"1" + b"}" * depth, headers=_h())
    assert r.status_code == 400, r.text
    assert "nested too deeply" in r.json()["error"]
    assert r2.status_code == 400 and "nested too deeply" in r2.json()["error"]
    assert not [rec for rec in caplog.records if rec.exc_info or rec.levelno >= logging.ERROR]
    assert client.get("/api/state", headers=_h()).json()["pairs"] == []  # still serving


# ------------------------------------------------------------------------------ body size


def test_a_body_over_the_limit_is_a_413(client):
    r = client.post("/api/pairs", content=b" " * (MAX_BODY_BYTES + 1), headers=_h())
    assert r.status_code == 413, r.text
    assert "larger than" in r.json()["error"]
    # the largest real request (a pair) is far below the limit
    assert client.post("/api/save", content=b" " * 1000, headers=_h()).status_code == 400


def test_a_declared_oversized_body_is_refused_unread(session):
    app = create_app(session, TOKEN)
    headers = {"host": "127.0.0.1:8765", "x-flexreg-token": TOKEN, "content-length": "100000000"}
    status, answer, read = _call(app, "POST", headers, [b"x" * 65536] * 40)
    assert status == 413 and "larger than" in answer["error"]
    assert read == 0
    headers["content-length"] = "12abc"
    status, answer, read = _call(app, "POST", headers, [b"{}"])
    assert status == 400 and "Content-Length" in answer["error"] and read == 0


def test_a_chunked_body_is_read_no_further_than_the_limit(session):
    app = create_app(session, TOKEN)
    headers = {"host": "127.0.0.1:8765", "x-flexreg-token": TOKEN}  # no Content-Length
    chunk = 65536
    status, answer, read = _call(app, "POST", headers, [b"x" * chunk] * 40)
    assert status == 413 and "larger than" in answer["error"]
    assert read * chunk <= MAX_BODY_BYTES + chunk  # stopped at the first chunk past the limit
    # a small chunked body still gets through, whole
    status, answer, _ = _call(app, "POST", headers, [b'{"u": 1, ', b'"v": 2}'])
    assert status == 400 and "x: expected a number" in answer["error"]


# ------------------------------------------------------------------------------ origin


@pytest.mark.parametrize(
    "origin",
    ["http://evil.example", "http://evil.example:8765", "http://127.0.0.1:9999", "null",
     "https://127.0.0.1:8765", "http://127.0.0.1:bad"],
)  # fmt: skip
def test_state_changes_from_another_origin_are_refused(client, session, origin):
    click = true_clicks(session.views.range_image, 1)[0]
    r = client.post("/api/pairs", json=click, headers={**_h(), "Origin": origin})
    assert r.status_code == 403, r.text
    assert "origin" in r.json()["error"]
    assert client.delete("/api/pairs/1", headers={**_h(), "Origin": origin}).status_code == 403
    assert client.post("/api/save", headers={**_h(), "Origin": origin}).status_code == 403
    assert session.pairs == {}


@pytest.mark.parametrize("origin", [BASE, None, "http://127.0.0.1:8765/"])
def test_state_changes_from_the_page_or_without_origin_pass(client, session, origin):
    click = true_clicks(session.views.range_image, 1)[0]
    headers = _h() if origin is None else {**_h(), "Origin": origin}
    r = client.post("/api/pairs", json=click, headers=headers)
    assert r.status_code == 200, r.text
    assert len(r.json()["pairs"]) == 1


def test_the_origin_follows_the_host_the_page_was_opened_at(session):
    c = TestClient(create_app(session, TOKEN), base_url="http://localhost:4321")
    click = true_clicks(session.views.range_image, 1)[0]
    ok = c.post("/api/pairs", json=click, headers={**_h(), "Origin": "http://localhost:4321"})
    assert ok.status_code == 200, ok.text
    bad = c.post("/api/pairs", json=click, headers={**_h(), "Origin": BASE})
    assert bad.status_code == 403


# ------------------------------------------------------------------------------ save


def test_save_writes_at_once_inside_the_commands_block(client, session, tmp_path):
    """The command line runs `pick` inside all_or_nothing(): Save must still put complete
    files on disk at once (the terminal may close before the command ends)."""
    out = tmp_path / "out"
    clicks = true_clicks(session.views.range_image, 8)
    with all_or_nothing():
        for c in clicks[:7]:
            assert client.post("/api/pairs", json=c, headers=_h()).status_code == 200
        r = client.post("/api/save", headers=_h())
        assert r.status_code == 200 and r.json()["saved"]
        assert _uv(out / "pairs.csv") == [[c["u"], c["v"]] for c in clicks[:7]]
        doc = json.loads((out / "pairs-calib.json").read_text())
        assert len(doc["pairs"]) == 7
        # a later Save replaces both, at once too
        assert client.post("/api/pairs", json=clicks[7], headers=_h()).status_code == 200
        assert client.post("/api/save", headers=_h()).status_code == 200
        assert _uv(out / "pairs.csv") == [[c["u"], c["v"]] for c in clicks]
        assert len(json.loads((out / "pairs-calib.json").read_text())["pairs"]) == 8
        before = {p.name: p.read_bytes() for p in out.iterdir()}
    # the block's end writes nothing more; no temporaries are left behind
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(before) == ["pairs-calib.json", "pairs.csv"]
    assert len(read_correspondences(out / "pairs.csv")) == 8


def _uv(path) -> list[list[float]]:
    """The ``u,v`` columns of a saved pairs file, read as plain text (reading it with
    :func:`read_correspondences` inside the block would make it an input of the block)."""
    rows = [line.split(",") for line in path.read_text().splitlines() if line[:1] not in "#u"]
    return [[float(r[0]), float(r[1])] for r in rows]


def test_save_is_both_or_neither(session, tmp_path, monkeypatch):
    import flexreg.picker.session as mod

    for c in true_clicks(session.views.range_image, 7):
        session.add_pair(c["u"], c["v"], c["mode"], c["x"], c["y"])
    session.save()
    out = tmp_path / "out"
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    session.delete_pair(next(iter(session.pairs)))

    def broken(path, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mod, "write_transform_json", broken)
    with all_or_nothing(), pytest.raises(InputError, match="No space left"):
        session.save()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not session.state()["saved"]
