"""Pydantic model classes build their validator and serializer at first use, not as their module is imported
(issue 33: ~320 classes, DriveBench's and FastAPI's OpenAPI models, each built its core schema while a server started
before it could answer ``/api/health``; most are used later or never in a given process).

``defer_build`` on ``BaseModel``'s own configuration: every model class made after :func:`defer_builds` inherits it
(its ``model_config`` may still set it back). A deferred class is built, as pydantic builds it, by its first
validation, serialization, schema or a ``TypeAdapter`` over it (FastAPI's fields); pydantic >= 2.14 does that under
a lock, so two threads that first use a model at once get the same validator. Validation, errors and the OpenAPI
document do not change."""

from __future__ import annotations

from pydantic import BaseModel


def defer_builds() -> None:
    BaseModel.model_config["defer_build"] = True
