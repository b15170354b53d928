"""ChArUco calibration board: its geometry, a printable image, and detection of its corners in an image.

Board frame (OpenCV's): origin at the outer corner of the top-left square, x along the board's rows (to the
right in the printed image), y down the printed image, z into the board; metres. A board's identity is
:class:`ChArUcoBoard` (squares, sizes, ArUco dictionary), saved beside the printable image as JSON so the
calibration uses the board that was printed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

MIN_CORNERS = 6  # fewer interior corners than this give no reliable pose (solvePnP needs >= 4 non-collinear)
MM_PER_INCH = 25.4


@dataclass(frozen=True)
class BoardView:
    """The board's interior corners found in one image: ``ids`` (N,), ``pixels`` (N, 2) float64 (pixel centres
    at integer coordinates, OpenCV's convention and R&D's), ``points_board`` (N, 3) float64 in the board frame."""

    ids: np.ndarray
    pixels: np.ndarray
    points_board: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.shape[0])


@dataclass(frozen=True)
class ChArUcoBoard:
    """A ChArUco board: ``squares`` (columns, rows) of ``square_m`` metres, ArUco markers of ``marker_m``
    metres in the white squares, from OpenCV's predefined ``dictionary`` (e.g. ``DICT_5X5_100``)."""

    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.04
    marker_m: float = 0.03
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self) -> None:
        cols, rows = (int(v) for v in self.squares)
        object.__setattr__(self, "squares", (cols, rows))
        if cols < 3 or rows < 3:
            raise ValueError(f"board squares must be at least 3x3, got {cols}x{rows}")
        if not 0 < self.marker_m < self.square_m:
            raise ValueError(
                f"board marker_m ({self.marker_m}) must be positive and smaller than square_m ({self.square_m})"
            )
        if not hasattr(cv2.aruco, self.dictionary):
            known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
            raise ValueError(f"unknown ArUco dictionary {self.dictionary!r}; OpenCV knows {known}")
        if (cols * rows) // 2 > self._cv_dictionary().bytesList.shape[0]:
            raise ValueError(f"{self.dictionary} has too few markers for a {cols}x{rows} board: pick a larger one")

    # ------------------------------------------------------------------ OpenCV objects
    def _cv_dictionary(self):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def cv_board(self) -> cv2.aruco.CharucoBoard:
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, self._cv_dictionary())

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the chequered area in metres."""
        return self.squares[0] * self.square_m, self.squares[1] * self.square_m

    @property
    def n_corners(self) -> int:
        return (self.squares[0] - 1) * (self.squares[1] - 1)

    # ------------------------------------------------------------------ images
    def image(self, px_per_square: int = 100) -> np.ndarray:
        """The chequered area alone, (rows * px, cols * px) uint8 grey, no margin (a texture for simulation)."""
        cols, rows = self.squares
        return self.cv_board().generateImage((cols * px_per_square, rows * px_per_square), marginSize=0)

    def printable(self, dpi: int = 300, margin_mm: float = 10.0) -> np.ndarray:
        """A page image at ``dpi`` with the board at its true size, a white margin and a caption giving the
        square size to check the print with a ruler (printers scale pages: measure before calibrating)."""
        px_per_m = dpi / MM_PER_INCH * 1000.0
        px_sq = round(self.square_m * px_per_m)
        board = self.image(px_sq)
        margin = round(margin_mm / 1000.0 * px_per_m)
        caption_h = max(round(0.012 * px_per_m), 24)
        page = np.full((board.shape[0] + 2 * margin + caption_h, board.shape[1] + 2 * margin), 255, np.uint8)
        page[margin : margin + board.shape[0], margin : margin + board.shape[1]] = board
        text = (
            f"ChArUco {self.squares[0]}x{self.squares[1]} {self.dictionary}: square {self.square_m * 1000:.1f} mm, "
            f"marker {self.marker_m * 1000:.1f} mm (print at 100%, measure a square)"
        )
        scale = caption_h / 40.0
        cv2.putText(page, text, (margin, board.shape[0] + margin + int(0.8 * caption_h)),
                    cv2.FONT_HERSHEY_SIMPLEX, scale, 0, max(1, int(2 * scale)), cv2.LINE_AA)  # fmt: skip
        return page

    # ------------------------------------------------------------------ detection
    def detect(self, image: np.ndarray, min_corners: int = MIN_CORNERS) -> BoardView | None:
        """Interior corners of the board in ``image`` (H, W) grey or (H, W, 3) RGB uint8, refined to sub-pixel;
        None when fewer than ``min_corners`` are found."""
        img = np.asarray(image)
        if img.dtype != np.uint8:
            raise ValueError(f"board detection needs a uint8 image, got {img.dtype}")
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        elif img.ndim != 2:
            raise ValueError(f"board detection needs an (H, W) or (H, W, 3) image, got shape {img.shape}")
        corners, ids, _, _ = cv2.aruco.CharucoDetector(self.cv_board()).detectBoard(img)
        if ids is None or len(ids) < min_corners:
            return None
        ids = ids.reshape(-1).astype(np.int64)
        pts = self.cv_board().getChessboardCorners()[ids].astype(np.float64)
        return BoardView(ids, corners.reshape(-1, 2).astype(np.float64), pts)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["squares"] = list(self.squares)
        return {"format": "lerobot_rnd.charuco_board", **d}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ChArUcoBoard:
        d = dict(d)
        d.pop("format", None)
        unknown = set(d) - {"squares", "square_m", "marker_m", "dictionary"}
        if unknown:
            raise ValueError(f"board JSON: unknown keys {sorted(unknown)} (expected squares, square_m, marker_m, dictionary)")
        return cls(squares=tuple(d.get("squares", (7, 5))), square_m=float(d.get("square_m", 0.04)),
                   marker_m=float(d.get("marker_m", 0.03)), dictionary=str(d.get("dictionary", "DICT_5X5_100")))  # fmt: skip

    def save_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load_json(cls, path: str | Path) -> ChArUcoBoard:
        return cls.from_dict(json.loads(Path(path).read_text()))
