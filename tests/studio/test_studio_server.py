"""``saucerfab studio``: the subcommand, one server per workspace, the loopback warning's test."""

from __future__ import annotations

from pathlib import Path

import pytest

from saucerfab.cli import main
from saucerfab.files.fileio import exclusive_lock
from saucerfab.studio.server import is_loopback, url_of
from saucerfab.studio.workspace import Workspace


def test_help_lists_the_options(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["studio", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for opt in ("--port", "--host", "--workspace", "--open", "--jobs", "--max-upload-mb", "--token", "--token-file",
                "--no-auth", "no authentication"):
        assert opt in out


def test_a_second_server_on_one_workspace_stops_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ws = Workspace(tmp_path / "ws")
    with exclusive_lock(ws.root / ".lock", lambda: RuntimeError("held")):
        assert main(["studio", "--workspace", str(ws.root), "--port", "0"]) == 2
    assert "already serving" in capsys.readouterr().err


def test_bad_workspace_and_numbers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["studio", "--workspace", str(tmp_path)]) == 2
    assert "other files" in capsys.readouterr().err
    assert main(["studio", "--workspace", str(tmp_path / "w"), "--jobs", "0"]) == 2
    assert "--jobs" in capsys.readouterr().err


@pytest.mark.parametrize("host, loop", [("127.0.0.1", True), ("::1", True), ("localhost", True),
                                        ("0.0.0.0", False), ("192.168.1.4", False), ("studio.lan", False)])
def test_loopback(host: str, loop: bool) -> None:
    assert is_loopback(host) is loop


def test_url_of() -> None:
    assert url_of("0.0.0.0", 8000) == "http://127.0.0.1:8000/"
    assert url_of("::1", 80) == "http://[::1]:80/"


def test_banner_and_the_network_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    import uvicorn

    monkeypatch.delenv("SAUCERFAB_STUDIO_TOKEN", raising=False)  # a token of the shell running the tests
    served = []
    monkeypatch.setattr(uvicorn.Server, "run", lambda self: served.append(self.config.host))  # no real serving
    main(["studio", "--workspace", str(tmp_path / "ws"), "--host", "0.0.0.0", "--port", "0", "--no-auth"])
    out, err = capsys.readouterr()
    assert served == ["0.0.0.0"] and str(tmp_path / "ws") in out and "http://" in out
    assert "anyone on the network" in err and "no authentication" in err
    main(["studio", "--workspace", str(tmp_path / "ws"), "--port", "0"])
    assert "warning" not in capsys.readouterr().err


def test_jobs_and_a_scheduler_contradict_each_other(tmp_path, capsys) -> None:  # noqa: ANN001
    assert main(["studio", "--workspace", str(tmp_path / "w"), "--no-auth", "--jobs", "2",
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--jobs and --scheduler contradict" in capsys.readouterr().err
    assert not (tmp_path / "w").exists()  # refused before anything was made


def test_open_keeps_the_token_off_the_browsers_command_line(tmp_path: Path) -> None:
    """--open gives the browser a page only this user can read, which goes on to the URL with the token."""
    import stat

    from saucerfab.studio.server import OPEN_PAGE, browser_target

    assert browser_target("http://127.0.0.1:8000/", tmp_path) == "http://127.0.0.1:8000/"  # no token: as it is
    secret = "s3cret-token-of-the-test-0123456789"
    target = browser_target(f"http://127.0.0.1:8000/?token={secret}", tmp_path)
    assert secret not in target and target == (tmp_path / OPEN_PAGE).resolve().as_uri()
    page = tmp_path / OPEN_PAGE
    assert stat.S_IMODE(page.stat().st_mode) == 0o600
    assert f'url=http://127.0.0.1:8000/?token={secret}"' in page.read_text()
    assert not list(tmp_path.glob("*.tmp"))
