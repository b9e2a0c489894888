"""``saucerfab studio``: the local web application (designs, looks, results, exports in a browser)."""

from __future__ import annotations

import argparse

HELP = "the studio: design, watch, compare and export in a browser page (a local web server)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options; their defaults are the studio's own (saucerfab.studio.server, .workspace)."""
    from saucerfab.studio.auth import TOKEN_ENV
    from saucerfab.studio.jobs import DEFAULT_JOBS
    from saucerfab.studio.server import DEFAULT_HOST, DEFAULT_PORT, DEFAULT_WORKSPACE
    from saucerfab.studio.workspace import MAX_UPLOAD_BYTES, SHARED_USER

    p.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"port to serve on (default {DEFAULT_PORT})")
    p.add_argument(
        "--host",
        default=DEFAULT_HOST,
        help=f"address to serve on (default {DEFAULT_HOST}: this machine only). Another address shares the studio "
        f"on the network and needs a token (--token-file, ${TOKEN_ENV}, --token) or --no-auth",
    )
    p.add_argument("--token", metavar="TOKEN",
                   help="the token that signs in (default: a random one, printed in the studio's URL at start). "
                   f"Other users of this machine can read it in the process list: services give ${TOKEN_ENV} "
                   "or --token-file")
    p.add_argument("--token-file", metavar="FILE",
                   help="a file of one token, or of lines USER:TOKEN: each user sees only their own designs "
                   f"and uploads, and the user {SHARED_USER!r} sees everyone's")
    p.add_argument("--no-auth", action="store_true",
                   help="no sign-in: anyone who can reach the studio uses it and its files (no authentication)")
    p.add_argument("--workspace", default=str(DEFAULT_WORKSPACE),
                   help=f"folder of the studio's uploads and designs (default {DEFAULT_WORKSPACE}; created)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser once it is up")
    p.add_argument("--jobs", type=int, default=DEFAULT_JOBS,
                   help=f"designs and exports run at once (default {DEFAULT_JOBS}: a design already uses every core)")
    p.add_argument("--max-upload-mb", type=float, default=MAX_UPLOAD_BYTES / 2**20,
                   help=f"largest upload, MiB (default {MAX_UPLOAD_BYTES / 2**20:g})")


def run(args: argparse.Namespace) -> int:
    from saucerfab.extras import require

    require("studio", "design", "verify")  # the server, and the designs and exports it runs

    from saucerfab.studio.server import serve

    return serve(args.workspace, host=args.host, port=args.port, jobs=args.jobs,
                 max_upload_bytes=int(args.max_upload_mb * 2**20), open_browser=args.open,
                 token=args.token, token_file=args.token_file, no_auth=args.no_auth)
