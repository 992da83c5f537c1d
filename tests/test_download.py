"""Detection registry and downloader, against a local HTTP server on 127.0.0.1 started inside the test:
a plain download with SHA-256 check, a wrong checksum, a connection broken mid-file and then resumed with a
Range request, resume of a partial file left by an earlier run, and browser-only hosts."""

from __future__ import annotations

import hashlib
import re
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from grutrack.cli import main
from grutrack.data.download import DownloadError, download, fetch_source, needs_browser
from grutrack.data.registry import DetectionSource, load_registry
from grutrack.errors import ConfigError

DATA = bytes((i * 7919 + i // 13) % 251 for i in range(300_000))
SHA = hashlib.sha256(DATA).hexdigest()


class _Handler(BaseHTTPRequestHandler):
    """Serves DATA at any path; honours Range; /broken closes the first full response half-way."""

    requests: list[str | None] = []
    broke = False

    def do_GET(self):  # noqa: N802 (http.server API)
        rng = self.headers.get("Range")
        type(self).requests.append(rng)
        start = int(re.match(r"bytes=(\d+)-", rng).group(1)) if rng else 0
        body = DATA[start:]
        if self.path == "/broken" and not type(self).broke and start == 0:
            type(self).broke = True
            self.send_response(200)
            self.send_header("Content-Length", str(len(DATA)))
            self.end_headers()
            self.wfile.write(DATA[: len(DATA) // 2])
            self.wfile.flush()
            self.close_connection = True
            return
        self.send_response(206 if rng else 200)
        if rng:
            self.send_header("Content-Range", f"bytes {start}-{len(DATA) - 1}/{len(DATA)}")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):  # keep the test output clean
        pass


@pytest.fixture()
def server():
    """Base URL of a local server that stops when the test ends."""
    _Handler.requests, _Handler.broke = [], False
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=5)


def _source(url: str | None, host: str = "direct", sha: str | None = None) -> DetectionSource:
    return DetectionSource(
        name="test_src",
        dataset="nuscenes",
        detector="cp",
        split="val",
        description="test file.",
        page="https://example.org",
        url=url,
        host=host,
        filename="dets.json",
        sha256=sha,
        format="nuscenes_json",
        member=None,
    )


def test_download_verifies_checksum_and_renames(server, tmp_path):
    dest = tmp_path / "d" / "file.json"
    assert download(f"{server}/file.json", dest, SHA, progress=False, timeout=5) == SHA
    assert dest.read_bytes() == DATA
    assert not (tmp_path / "d" / "file.json.part").exists()


def test_wrong_checksum_leaves_no_file(server, tmp_path):
    dest = tmp_path / "file.json"
    with pytest.raises(DownloadError, match="SHA-256 mismatch"):
        download(f"{server}/file.json", dest, "0" * 64, progress=False, timeout=5)
    assert not dest.exists() and not (tmp_path / "file.json.part").exists()


def test_broken_connection_is_resumed_with_range(server, tmp_path):
    dest = tmp_path / "file.json"
    download(f"{server}/broken", dest, SHA, progress=False, timeout=5, retries=2)
    assert dest.read_bytes() == DATA
    assert _Handler.requests[0] is None and _Handler.requests[1] == f"bytes={len(DATA) // 2}-"


def test_partial_file_of_an_earlier_run_is_resumed(server, tmp_path):
    dest = tmp_path / "file.json"
    (tmp_path / "file.json.part").write_bytes(DATA[:1000])
    download(f"{server}/file.json", dest, SHA, progress=False, timeout=5)
    assert dest.read_bytes() == DATA and _Handler.requests == ["bytes=1000-"]


def test_fetch_source_and_cli(server, tmp_path, capsys):
    assert fetch_source(_source(f"{server}/x", sha=SHA), tmp_path, progress=False).read_bytes() == DATA
    # a file already in place (e.g. put there by hand) is verified, not downloaded again
    n = len(_Handler.requests)
    fetch_source(_source(f"{server}/x", sha=SHA), tmp_path, progress=False)
    assert len(_Handler.requests) == n
    out = tmp_path / "cli"
    assert (
        main(
            [
                "download-detections",
                "centerpoint_val",
                "--out",
                str(out),
                "--url",
                f"{server}/cp.json",
                "--sha256",
                SHA,
                "--no-progress",
            ]
        )
        == 0
    )
    assert (out / "centerpoint_val.json").read_bytes() == DATA
    assert "ready" in capsys.readouterr().out


def test_browser_host_and_unknown_url_say_where_to_put_the_file(tmp_path):
    with pytest.raises(DownloadError, match=f"put it at {re.escape(str(tmp_path / 'dets.json'))}"):
        fetch_source(_source("https://drive.google.com/file/d/abc/view", host="browser"), tmp_path)
    with pytest.raises(DownloadError, match="no public download link is known"):
        fetch_source(_source(None, host="browser"), tmp_path)
    assert needs_browser("https://drive.google.com/x") and not needs_browser("http://127.0.0.1/x")


def test_cli_error_for_registry_source_on_google_drive(tmp_path, capsys):
    assert main(["download-detections", "centerpoint_test", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "needs a browser" in err and str(tmp_path / "centerpoint_test.json") in err


def test_registry_entries_and_validation(tmp_path):
    reg = load_registry()
    assert {
        "centerpoint_val",
        "centerpoint_test",
        "centerpoint_train",
        "largekernel3d_val",
        "largekernel3d_test",
        "lt3d_val",
    } <= set(reg)
    assert reg["lt3d_val"].dataset == "av2" and reg["centerpoint_test"].split == "test"
    bad = tmp_path / "reg.yaml"
    bad.write_text("sources:\n  x: {dataset: nuscenes, detecter: cp}\n")
    with pytest.raises(ConfigError, match="unknown key 'sources.x.detecter'"):
        load_registry(bad)


def test_download_fails_clearly_on_http_error(server, tmp_path, monkeypatch):
    def refuse(self):
        self.send_error(404, "Not Found")

    monkeypatch.setattr(_Handler, "do_GET", refuse)
    with pytest.raises(DownloadError, match="HTTP 404"):
        download(f"{server}/missing", Path(tmp_path) / "m.json", progress=False, timeout=5)


def test_extract_member_writes_whole_file_or_clear_error(tmp_path):
    import zipfile

    from grutrack.data.nusc_convert import extract_member
    from grutrack.errors import InputFormatError

    z = tmp_path / "a.zip"
    with zipfile.ZipFile(z, "w") as zf:
        zf.writestr("x/det.json", '{"results": {}}')
    out = extract_member(z, "x/det.json", tmp_path)
    assert out.read_text() == '{"results": {}}'
    with pytest.raises(InputFormatError, match="no member 'nope'"):
        extract_member(z, "nope", tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.zip", "det.json"]  # no temp file left
