"""The contents manager ``python -m course lab`` serves files with (``course/lab.py`` says why).

JupyterLab's own file manager, except that a notebook shipped with the course (``lab.is_shipped``) is reported as
not writable, which makes JupyterLab skip its autosave and offer *Save As* on Ctrl+S, and a save onto one is
refused (HTTP 403) with a message naming ``work/``. Saving anywhere else, a copy of a shipped notebook into
``work/`` included, is unchanged.
"""
from __future__ import annotations

from jupyter_server.services.contents.largefilemanager import AsyncLargeFileManager
from tornado import web

from .lab import READ_ONLY_MESSAGE, is_shipped

__all__ = ["CourseContentsManager"]


class CourseContentsManager(AsyncLargeFileManager):
    """``AsyncLargeFileManager`` with the course's shipped notebooks read-only."""

    async def get(self, path, *args, **kwargs):
        model = await super().get(path, *args, **kwargs)
        if model.get("type") == "notebook" and is_shipped(model.get("path", path)):
            model["writable"] = False
        return model

    async def save(self, model, path=""):
        if is_shipped(path.strip("/")):
            raise web.HTTPError(403, READ_ONLY_MESSAGE.format(path=path.strip("/")))
        return await super().save(model, path)
