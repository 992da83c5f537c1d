"""Downloading detection files: HTTP(S) with a progress bar, range resume, SHA-256 check and an atomic rename.

The bytes go to ``<dest>.part``; an interrupted transfer (broken connection, timeout, a short body) is resumed
with an HTTP ``Range`` request, within one call (``retries``) and across calls (the ``.part`` file is kept).
Only a complete file whose SHA-256 matches (when one is expected) is renamed onto ``dest``, so ``dest`` never
holds a partial or corrupt file. Hosts that need a browser (Google Drive, OneDrive, ...) are not scraped: the
error says where to put the file by hand.
"""

from __future__ import annotations

import http.client
import os
import re
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import urlparse

from tqdm import tqdm

from grutrack import __version__
from grutrack.data.registry import DetectionSource
from grutrack.errors import GrutrackError
from grutrack.provenance import sha256_file

#: hosts whose links open a web page (sign-in, virus-scan interstitial, folder view) rather than the file
BROWSER_HOSTS = (
    "drive.google.com",
    "docs.google.com",
    "drive.usercontent.google.com",
    "onedrive.live.com",
    "1drv.ms",
    "sharepoint.com",
    "pan.baidu.com",
    "dropbox.com",
)
CHUNK = 1 << 16


class DownloadError(GrutrackError):
    """A download cannot be done (here): the message says why and what to do instead."""


class _Interrupted(Exception):
    """The transfer stopped early; resume with a Range request."""


def needs_browser(url: str) -> bool:
    """True when ``url`` points at a host that only serves the file through a browser."""
    host = (urlparse(url).hostname or "").lower()
    return any(host == h or host.endswith("." + h) for h in BROWSER_HOSTS)


def manual_instructions(src: DetectionSource, dest: Path, reason: str) -> str:
    """The message for a file that has to be put in place by hand."""
    where = f"open {src.url} in a browser, download the file" if src.url else "obtain the file as described below"
    check = f" Its SHA-256 must be {src.sha256}." if src.sha256 else ""
    return (
        f"detection source '{src.name}' cannot be downloaded automatically: {reason}. To use it, {where} "
        f"and put it at {dest} (then re-run).{check} About the file: {' '.join(src.description.split())} "
        f"(source: {src.page})"
    )


def fetch_source(
    src: DetectionSource,
    out_dir: str | Path,
    *,
    url: str | None = None,
    sha256: str | None = None,
    progress: bool = True,
    retries: int = 5,
    timeout: float = 30.0,
) -> Path:
    """Make ``out_dir/<src.filename>`` exist and verified: keep a file already there (checked against the
    expected SHA-256 when one is known), else download it. ``url`` / ``sha256`` override the registry's."""
    dest = src.raw_path(out_dir)
    expected = sha256 or src.sha256
    if dest.is_file():
        _verify_existing(dest, expected)
        return dest
    link = url or src.url
    if link is None:
        raise DownloadError(manual_instructions(src, dest, "no public download link is known"))
    if url is None and (src.host == "browser" or needs_browser(link)):
        raise DownloadError(manual_instructions(src, dest, f"its host ({urlparse(link).hostname}) needs a browser"))
    if needs_browser(link):
        raise DownloadError(
            f"{link}: this host ({urlparse(link).hostname}) needs a browser; download the file by "
            f"hand and put it at {dest}"
        )
    digest = download(link, dest, expected, progress=progress, retries=retries, timeout=timeout)
    if not expected:
        print(
            f"note: no SHA-256 is registered for '{src.name}'; the downloaded file has sha256 {digest}", file=sys.stderr
        )
    return dest


def _verify_existing(dest: Path, expected: str | None) -> None:
    """Check a file that is already in place (downloaded before or put there by hand)."""
    if expected:
        got = sha256_file(dest)
        if got != expected:
            raise DownloadError(
                f"{dest}: SHA-256 is {got}, expected {expected}; the file is not the registered "
                f"one (remove it and download again)"
            )


def download(
    url: str,
    dest: str | Path,
    sha256: str | None = None,
    *,
    progress: bool = True,
    retries: int = 5,
    timeout: float = 30.0,
) -> str:
    """Download ``url`` to ``dest`` (resuming ``dest.part``), verify, rename atomically; returns the SHA-256."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    part = dest.with_name(dest.name + ".part")
    for attempt in range(retries + 1):
        try:
            _transfer(url, part, timeout, progress)
            break
        except (TimeoutError, _Interrupted, ConnectionError, http.client.HTTPException, urllib.error.URLError) as exc:
            if isinstance(exc, urllib.error.HTTPError):
                raise DownloadError(f"{url}: HTTP {exc.code} {exc.reason}") from exc
            if attempt == retries:
                size = part.stat().st_size if part.exists() else 0
                raise DownloadError(
                    f"{url}: transfer failed after {retries + 1} attempts ({exc}); {size} bytes are "
                    f"kept in {part} and the next run resumes from there"
                ) from exc
            print(f"download interrupted ({exc}); resuming", file=sys.stderr)
            time.sleep(min(0.2 * 2**attempt, 5.0))
    digest = sha256_file(part)
    if sha256 and digest != sha256:
        part.unlink()
        raise DownloadError(
            f"{url}: SHA-256 mismatch: got {digest}, expected {sha256} (the partial file was "
            f"removed; {dest} was not written)"
        )
    os.replace(part, dest)
    return digest


def _transfer(url: str, part: Path, timeout: float, progress: bool) -> None:
    """One request: continue ``part`` from its current size; raises :class:`_Interrupted` on a short body."""
    have = part.stat().st_size if part.exists() else 0
    headers = {"User-Agent": f"grutrack/{__version__}"}
    if have:
        headers["Range"] = f"bytes={have}-"
    try:
        resp = urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and have and _complete_size(exc.headers.get("Content-Range")) == have:
            return  # the partial file already holds every byte
        raise
    with resp:
        start = _range_start(resp, have)
        length = resp.headers.get("Content-Length")
        total = start + int(length) if length is not None else None
        _copy_body(resp, part, start, total, progress, url)


def _range_start(resp, have: int) -> int:
    """Offset the response body starts at: ``have`` for a matching 206, 0 when the server sent everything."""
    if resp.status == 206:
        m = re.match(r"bytes (\d+)-", resp.headers.get("Content-Range", ""))
        if not m or int(m.group(1)) != have:
            raise _Interrupted(f"server answered the range request with {resp.headers.get('Content-Range')!r}")
        return have
    return 0


def _complete_size(content_range: str | None) -> int | None:
    """Total size from a 416 answer's ``Content-Range: bytes */N``."""
    m = re.match(r"bytes \*/(\d+)", content_range or "")
    return int(m.group(1)) if m else None


def _copy_body(resp, part: Path, start: int, total: int | None, progress: bool, url: str) -> None:
    """Append the body to ``part`` (or rewrite it when ``start`` is 0), with a progress bar."""
    name = Path(urlparse(url).path).name or "download"
    with (
        open(part, "r+b" if start and part.exists() else "wb") as f,
        tqdm(
            total=total,
            initial=start,
            unit="B",
            unit_scale=True,
            unit_divisor=1024,
            desc=name,
            disable=not progress,
            file=sys.stderr,
        ) as bar,
    ):
        f.seek(start)
        f.truncate()
        while True:
            block = resp.read(CHUNK)
            if not block:
                break
            f.write(block)
            bar.update(len(block))
        f.flush()
        os.fsync(f.fileno())
        size = f.tell()
    if total is not None and size < total:
        raise _Interrupted(f"connection closed after {size} of {total} bytes")
