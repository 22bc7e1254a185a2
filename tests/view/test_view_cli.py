"""``gonio view`` without a browser: bad input writes nothing, the local server serves its page
only, at its token URL, on 127.0.0.1; ``gonio.view(obj)`` shows inline in Jupyter."""

from __future__ import annotations

import threading
import urllib.error
import urllib.request

import pytest


def test_unreadable_input_is_one_line_and_no_page(tmp_path, capsys):
    from gonio.cli import main

    bad = tmp_path / "bad.binary"
    bad.write_bytes(b"garbage")
    out = tmp_path / "view.html"
    rc = main(["view", str(bad), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc != 0 and err.count("\n") == 1 and "bad.binary" in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


def test_missing_fit_is_one_line(tmp_path, capsys):
    from gonio.cli import main

    rc = main(["view", str(tmp_path / "no.json"), "--out", str(tmp_path / "v.html")])
    err = capsys.readouterr().err
    assert rc != 0 and err.count("\n") == 1 and "not found" in err
    assert not (tmp_path / "v.html").exists()


def test_server_serves_only_its_page_on_loopback():
    from gonio.view.server import serve

    box = {}
    started = threading.Event()

    def ready(server):
        box["server"] = server
        started.set()

    t = threading.Thread(
        target=serve,
        args=("<html>the page</html>",),
        kwargs={"open_browser": False, "ready": ready},
        daemon=True,
    )
    t.start()
    assert started.wait(10)
    server = box["server"]
    try:
        assert server.server_address[0] == "127.0.0.1"
        assert len(server.token) >= 32
        with urllib.request.urlopen(server.url, timeout=10) as r:
            assert r.status == 200 and r.read() == b"<html>the page</html>"
        host, port = server.server_address[:2]
        for path in ("/", "/etc/passwd", f"/{server.token}/../pyproject.toml", "/x" + server.token):
            with pytest.raises(urllib.error.HTTPError) as e:
                urllib.request.urlopen(f"http://{host}:{port}{path}", timeout=10)
            assert e.value.code == 404, path
    finally:
        server.shutdown()
        t.join(10)


def test_gonio_view_is_callable_and_shows_inline(monkeypatch):
    import gonio.view
    import gonio.view.page
    from gonio.brdf import models

    monkeypatch.setattr(gonio.view.page, "build_page", lambda sources: f"<p>{sources[0].label}</p>")
    shown = gonio.view(models.Lambert(albedo=0.5), labels=["white"])
    html = shown._repr_html_()
    assert html.startswith("<iframe srcdoc=") and "&lt;p&gt;white&lt;/p&gt;" in html
