"""DriveBench: browser-based commissioning of CANopen drives."""

__version__ = "0.1.0"
