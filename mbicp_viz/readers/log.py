"""What every reader returns: the scans of a file, and the odometry it stores."""

from __future__ import annotations

from dataclasses import dataclass, field

from core import Pose2, Scan


@dataclass
class ScanLog:
    path: str
    scans: list[Scan]
    odometry: list[tuple[float, Pose2]] = field(default_factory=list)  # (stamp [s], pose) from ODOM lines
    skipped: dict[str, int] = field(default_factory=dict)  # message type -> lines skipped

    def __len__(self) -> int:
        return len(self.scans)

    def scan(self, index: int) -> Scan:
        from ..errors import InputError

        if not -len(self.scans) <= index < len(self.scans):
            raise InputError(f"scan index {index} out of range: the log holds {len(self.scans)} scans",
                             self.path, field="index")
        return self.scans[index]
