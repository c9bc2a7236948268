"""DriveBench: browser-based commissioning of CANopen drives."""

from drivebench.model_builds import defer_builds

__version__ = "0.1.0"

defer_builds()  # before FastAPI, pydantic-settings or a module of ours makes its model classes (issue 33)
