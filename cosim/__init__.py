"""navcosim orchestrator: scenarios, components, master algorithm, lidar, MCAP logs, CLI."""

from cosim.errors import CosimError

__all__ = ["CosimError"]
