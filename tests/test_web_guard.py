"""lipsync.web: Host/Origin/token/body-size guard, path confinement, serving on a real socket."""

import os
import socket

import httpx
import pytest
from starlette.applications import Starlette
from starlette.responses import JSONResponse, PlainTextResponse
from starlette.routing import Route, WebSocketRoute
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from lipsync.web import Guard, PathRefused, Session, resolve_inside, start_in_thread


async def echo(request):
    body = await request.body()
    return JSONResponse({"n": len(body)})


async def ws_echo(websocket):
    await websocket.accept()
    await websocket.send_text("hello")
    await websocket.close()


def make_app(session, **kw):
    app = Starlette(routes=[Route("/", lambda r: PlainTextResponse("page")),
                            Route("/api/echo", echo, methods=["POST", "GET"]),
                            WebSocketRoute("/ws", ws_echo)])
    return Guard(app, session=session, **kw)


@pytest.fixture
def session():
    s = Session.open()
    yield s
    s.close()


@pytest.fixture
def client(session):
    return TestClient(make_app(session, max_body=1000), base_url=session.origin)


def test_port_zero_binds_a_real_free_port(session):
    assert session.port > 0
    probe = socket.socket()
    with pytest.raises(OSError):  # it is really taken
        probe.bind(("127.0.0.1", session.port))
    probe.close()
    assert session.url("/") == f"http://127.0.0.1:{session.port}/?token={session.token}"
    assert len(session.token) >= 40  # 32 random bytes, base64


def test_tokens_differ_between_sessions():
    a, b = Session.open(), Session.open()
    try:
        assert a.token != b.token and a.port != b.port
    finally:
        a.close(), b.close()


def test_token_required_on_api_not_on_page(client, session):
    assert client.get("/").text == "page"
    assert client.get("/api/echo").status_code == 403
    assert client.get("/api/echo?token=wrong").status_code == 403
    assert client.get(f"/api/echo?token={session.token}").json() == {"n": 0}
    assert client.get("/api/echo", headers={"X-Lipsync-Token": session.token}).status_code == 200


@pytest.mark.parametrize("host", ["evil.example", "evil.example:80", "127.0.0.1", "127.0.0.1:1", "localhost"])
def test_foreign_host_refused(client, session, host):
    r = client.get(f"/api/echo?token={session.token}", headers={"host": host})
    assert r.status_code == 403 and "Host" in r.text


def test_local_host_names_accepted(client, session):
    for host in (f"127.0.0.1:{session.port}", f"localhost:{session.port}", f"LOCALHOST:{session.port}"):
        assert client.get(f"/api/echo?token={session.token}", headers={"host": host}).status_code == 200


@pytest.mark.parametrize("origin", ["http://evil.example", "null", "http://127.0.0.1", "https://127.0.0.1:1"])
def test_foreign_origin_refused(client, session, origin):
    r = client.post(f"/api/echo?token={session.token}", content=b"x", headers={"origin": origin})
    assert r.status_code == 403 and "Origin" in r.text


def test_own_origin_accepted(client, session):
    r = client.post(f"/api/echo?token={session.token}", content=b"xyz", headers={"origin": session.origin})
    assert r.json() == {"n": 3}


def test_body_size_bound(client, session):
    url = f"/api/echo?token={session.token}"
    assert client.post(url, content=b"a" * 1000).json() == {"n": 1000}
    assert client.post(url, content=b"a" * 1001).status_code == 413

    def chunks():  # no Content-Length: chunked, bounded while reading
        for _ in range(50):
            yield b"b" * 100
    assert client.post(url, content=chunks()).status_code == 413


def test_security_headers(client, session):
    r = client.get("/")
    assert r.headers["referrer-policy"] == "no-referrer"
    assert "frame-ancestors 'none'" in r.headers["content-security-policy"]


def test_websocket_guarded(client, session):
    ws_url = f"ws://127.0.0.1:{session.port}/ws"
    with client.websocket_connect(f"{ws_url}?token={session.token}", headers={"origin": session.origin}) as ws:
        assert ws.receive_text() == "hello"
    with pytest.raises(WebSocketDisconnect):
        with client.websocket_connect(ws_url) as ws:
            ws.receive_text()
    with pytest.raises(WebSocketDisconnect):
        with client.websocket_connect(f"{ws_url}?token={session.token}", headers={"origin": "http://evil.example"}) as ws:
            ws.receive_text()


def test_real_uvicorn_on_loopback(session):
    running = start_in_thread(make_app(session, max_body=1000), session)
    try:
        assert httpx.get(session.url("/api/echo")).json() == {"n": 0}
        assert httpx.get(f"{session.origin}/api/echo").status_code == 403
        r = httpx.post(session.url("/api/echo"), content=b"z" * 5000)
        assert r.status_code == 413
        # the server keeps serving after refusals
        assert httpx.post(session.url("/api/echo"), content=b"z" * 10).json() == {"n": 10}
    finally:
        running.stop()


def test_resolve_inside(tmp_path):
    root = tmp_path / "bank"
    (root / "sub").mkdir(parents=True)
    (root / "a.png").write_bytes(b"1")
    (root / "sub" / "b.png").write_bytes(b"2")
    (tmp_path / "secret.txt").write_text("s")
    os.symlink(tmp_path / "secret.txt", root / "link.txt")
    os.symlink(root / "a.png", root / "inner_link.png")
    assert resolve_inside(root, "a.png") == (root / "a.png").resolve()
    assert resolve_inside(root, "sub/../sub/b.png") == (root / "sub" / "b.png").resolve()
    assert resolve_inside(root, "inner_link.png") == (root / "a.png").resolve()
    for bad in ["../secret.txt", "sub/../../secret.txt", str(tmp_path / "secret.txt"), "link.txt",
                "", ".", "nope.png", "a.png\x00.txt", "~/x"]:
        with pytest.raises(PathRefused):
            resolve_inside(root, bad)
    assert resolve_inside(root, "new.yaml", must_exist=False) == (root / "new.yaml").resolve()


def test_bad_content_length(client, session):
    r = client.post(f"/api/echo?token={session.token}", content=b"x", headers={"content-length": "abc"})
    assert r.status_code == 400


@pytest.mark.parametrize("name", ["origin", "host", "x-lipsync-token"])
def test_repeated_host_origin_or_token_is_refused(client, session, name):
    # A valid value first and a foreign one second passed when only the first was read.
    good = {"origin": session.origin, "host": f"127.0.0.1:{session.port}", "x-lipsync-token": session.token}[name]
    bad = {"origin": "http://evil.example", "host": "evil.example", "x-lipsync-token": "nope"}[name]
    for pair in ([good, bad], [good, good]):
        headers = [(name, v) for v in pair] + ([] if name == "host" else [("host", f"127.0.0.1:{session.port}")])
        r = client.post(f"/api/echo?token={session.token}", content=b"x", headers=headers)
        assert r.status_code == 400 and "more than once" in r.text, (pair, r.status_code, r.text)
    assert client.post(f"/api/echo?token={session.token}", content=b"x",
                       headers={"origin": session.origin}).json() == {"n": 1}


def test_repeated_origin_refused_by_the_real_server(session):
    import socket

    running = start_in_thread(make_app(session, max_body=1000), session)
    try:
        for origins in ([session.origin, "http://evil.example"], [session.origin]):
            request = (f"POST /api/echo?token={session.token} HTTP/1.1\r\nHost: 127.0.0.1:{session.port}\r\n"
                       + "".join(f"Origin: {o}\r\n" for o in origins)
                       + "Content-Length: 1\r\nConnection: close\r\n\r\nx").encode()
            with socket.create_connection(("127.0.0.1", session.port), timeout=10) as sock:
                sock.sendall(request)
                reply = b""
                while chunk := sock.recv(65536):
                    reply += chunk
            status = int(reply.split(b" ", 2)[1])
            assert status == (400 if len(origins) == 2 else 200), reply[:300]
    finally:
        running.stop()
