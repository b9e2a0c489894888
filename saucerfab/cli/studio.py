"""``saucerfab studio``: the local web application (designs, looks, results, exports in a browser)."""

from __future__ import annotations

import argparse

HELP = "the studio: design, watch, compare and export in a browser page (a local web server)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options; their defaults are the studio's own (saucerfab.studio.server, .workspace)."""
    from saucerfab.studio.auth import TOKEN_ENV
    from saucerfab.studio.jobs import DEFAULT_JOBS, DEFAULT_MAX_QUEUED_PER_USER
    from saucerfab.studio.server import DEFAULT_HOST, DEFAULT_PORT, DEFAULT_WORKSPACE
    from saucerfab.studio.workspace import MAX_UPLOAD_BYTES, MAX_USER_UPLOAD_BYTES, SHARED_USER

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
    p.add_argument("--jobs", type=int,
                   help=f"designs and exports run at once on this machine (default {DEFAULT_JOBS}: a design already "
                   "uses every core); with --scheduler the cluster's threads decide")
    p.add_argument("--max-upload-mb", type=float, default=MAX_UPLOAD_BYTES / 2**20,
                   help=f"largest upload, MiB (default {MAX_UPLOAD_BYTES / 2**20:g})")
    p.add_argument("--max-user-upload-mb", type=float, default=MAX_USER_UPLOAD_BYTES / 2**20,
                   help=f"most MiB of uploads one user keeps, all together (default {MAX_USER_UPLOAD_BYTES / 2**20:g})")
    p.add_argument("--max-queued-per-user", type=int, default=DEFAULT_MAX_QUEUED_PER_USER,
                   help=f"designs one user may have waiting in the queue (default {DEFAULT_MAX_QUEUED_PER_USER}; "
                   "0: no limit), when the studio has several users (a --token-file of them). The users take turns: "
                   "round-robin, not first come")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run the designs and exports on this Dask scheduler's cluster (pip install "
                   "'saucerfab[cluster]'); the workspace must be on a filesystem its workers see at the same path")


def run(args: argparse.Namespace) -> int:
    from saucerfab.extras import require
    from saucerfab.studio.jobs import DEFAULT_JOBS

    require("studio", "design", "verify")  # the server, and the designs and exports it runs

    from saucerfab.errors import ConfigError
    from saucerfab.studio.server import serve

    if args.jobs is not None and args.scheduler:
        raise ConfigError("--jobs and --scheduler contradict each other: with --scheduler the Dask cluster's "
                          "threads decide how many designs run at once; give one of them")
    return serve(args.workspace, host=args.host, port=args.port, jobs=DEFAULT_JOBS if args.jobs is None else args.jobs,
                 max_upload_bytes=int(args.max_upload_mb * 2**20), open_browser=args.open,
                 token=args.token, token_file=args.token_file, no_auth=args.no_auth,
                 max_queued_per_user=args.max_queued_per_user,
                 max_user_upload_bytes=int(args.max_user_upload_mb * 2**20), scheduler=args.scheduler)
