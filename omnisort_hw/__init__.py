"""omnisort-hw: fisheye camera + laser-plane robotic sorting cell."""

__version__ = "0.1.0"
