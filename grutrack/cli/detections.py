"""``grutrack download-detections`` (a registry source into DIR: progress, range resume, SHA-256, atomic rename;
browser-only hosts: where to put the file by hand) and ``grutrack convert-detections`` (a downloaded file into
one split's detections, validated)."""

from __future__ import annotations

import argparse

from grutrack.data.registry import FORMATS, REGISTRY_PATH, get_source, load_registry
from grutrack.errors import ConfigError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``download-detections`` and ``convert-detections``."""
    p = sub.add_parser(
        "download-detections",
        help="download a registered detection file (or say where to put it)",
        description="Download a detection source of the registry (grutrack/configs/detections.yaml) "
        "into --out with a progress bar, HTTP range resume and SHA-256 verification; "
        "the file appears only when complete and verified. Sources on hosts that need "
        "a browser (Google Drive, ...) are not downloaded: the error says where to put "
        "the file by hand. --list shows the sources.",
    )
    p.add_argument("name", nargs="?", help="source name, e.g. centerpoint_val")
    p.add_argument("--out", help="folder to download into (the file keeps the registry's filename)")
    p.add_argument("--url", default=None, help="download from this URL instead (e.g. a mirror)")
    p.add_argument("--sha256", default=None, help="expected SHA-256 (overrides the registry's)")
    p.add_argument("--retries", type=int, default=5, help="resume attempts after a broken transfer (default 5)")
    p.add_argument("--timeout", type=float, default=30.0, help="socket timeout in seconds (default 30)")
    p.add_argument("--registry", default=str(REGISTRY_PATH), help="registry YAML (default: the shipped one)")
    p.add_argument("--list", action="store_true", help="list the registered sources and exit")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_download)

    p = sub.add_parser(
        "convert-detections",
        help="convert a downloaded detection file into one split's detections",
        description="Validate a downloaded detection file of a registry source against a split and "
        "write that split's detections: nuScenes detection JSON (every sample of the "
        "split present, boxes valid) or, for LT3D (AV2), a feather table of the "
        "split's logs. Written atomically.",
    )
    p.add_argument("name", nargs="?", help="registry source name (gives the format), e.g. centerpoint_val")
    p.add_argument(
        "--format",
        default=None,
        choices=FORMATS,
        help="format of a file that is not a registry source (instead of NAME)",
    )
    p.add_argument("--member", default=None, help="file inside the archive (with --format nuscenes_json_zip)")
    p.add_argument("--raw", required=True, help="the downloaded file")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot or AV2 sensor root")
    p.add_argument("--version", default=None, help="nuScenes version (nuScenes sources)")
    p.add_argument("--split", required=True, help="split the detections are for")
    p.add_argument("--out", required=True, help="converted detections (.json for nuScenes, .feather for LT3D)")
    p.add_argument("--registry", default=str(REGISTRY_PATH), help="registry YAML (default: the shipped one)")
    p.set_defaults(func=run_convert)


def run_download(args: argparse.Namespace) -> int:
    """Download (or verify a file already in place); prints the final path."""
    from grutrack.data.download import fetch_source

    if args.list:
        for name, src in load_registry(args.registry).items():
            link = src.url or "no public link"
            print(f"{name:<20} {src.dataset:<9} {src.split:<6} {src.host:<8} {link}")
        return 0
    if not args.name or not args.out:
        raise ConfigError("give a source NAME and --out DIR (or --list)")
    src = get_source(args.name, args.registry)
    dest = fetch_source(
        src,
        args.out,
        url=args.url,
        sha256=args.sha256,
        progress=not args.no_progress,
        retries=args.retries,
        timeout=args.timeout,
    )
    print(f"{dest}: ready ({src.description.split('.')[0]})")
    return 0


def run_convert(args: argparse.Namespace) -> int:
    """Convert by the source's format (a registry source's, or --format)."""
    if (args.name is None) == (args.format is None):
        raise ConfigError("give either a registry source NAME or --format")
    fmt, member = (
        (args.format, args.member)
        if args.format
        else (get_source(args.name, args.registry).format, get_source(args.name, args.registry).member)
    )
    if fmt == "nuscenes_json_zip" and not member:
        raise ConfigError("--format nuscenes_json_zip needs --member (the JSON inside the archive)")
    if fmt == "lt3d":
        from grutrack.data.lt3d_convert import convert_lt3d_detections, describe

        stats = convert_lt3d_detections(args.raw, args.dataroot, args.split, args.out)
    else:
        from grutrack.data.nusc_convert import convert_nuscenes_detections, describe

        if not args.version or args.version == "none":
            raise ConfigError("--version is required for nuScenes detection sources")
        stats = convert_nuscenes_detections(
            args.raw,
            args.dataroot,
            args.version,
            args.split,
            args.out,
            member=member if fmt == "nuscenes_json_zip" else None,
        )
    print(f"wrote {args.out}: {describe(stats)}")
    return 0
