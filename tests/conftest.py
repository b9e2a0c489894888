"""Test-wide set-up.

The tests mirror the package (``tests/render/`` for ``saucerfab/render/``,
and so on; a top-level module's tests stand here). The helper modules beside
this file - the slow references (``render_reference``, ``verify_reference``),
the mesh fixtures (``fixtures_check``), the conformance suites
(``conformance``) and the browser driver (``browser``) - import by name from
every test folder.
"""

from __future__ import annotations

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)


import pytest  # noqa: E402


@pytest.fixture(scope="module")
def chromium() -> None:
    """Debian's Chromium through Playwright (``browser.py``), started once; a missing browser FAILS the test.

    Page tests must run in CI, not skip there (``.ci/install-tools`` installs the browser).
    """
    import browser

    try:
        browser._browser()
    except browser.BrowserUnavailable as exc:
        pytest.fail(f"{exc}", pytrace=False)
