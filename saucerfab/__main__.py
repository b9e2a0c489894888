from saucerfab.cli import entry

entry()
