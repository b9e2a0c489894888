"""``saucerfab studio``: the local web application (issue 20).

A Starlette app (:mod:`saucerfab.studio.app`) under uvicorn
(:mod:`saucerfab.studio.server`) over a workspace folder
(:mod:`saucerfab.studio.workspace`); designs and exports run in worker
processes (:mod:`saucerfab.studio.jobs`, :mod:`saucerfab.studio.worker`).
The API contract and the workspace layout are in ``README.md`` beside this file.
"""
