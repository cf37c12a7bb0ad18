"""Materials of the procedural objects and scenes: laser reflectance (0..1) and colour."""

from __future__ import annotations

from flexreg.synth.mesh import Material

PLASTER = Material(0.78, (226, 222, 212))
CEILING = Material(0.82, (240, 240, 236))
CONCRETE = Material(0.5, (152, 150, 144))
SCREED = Material(0.42, (128, 126, 120))
PARQUET = Material(0.4, (168, 128, 84))
WOOD = Material(0.45, (150, 108, 66))
DARK_WOOD = Material(0.3, (96, 64, 40))
WHITE_PAINT = Material(0.85, (236, 236, 232))
METAL = Material(0.45, (160, 164, 170))
DARK_METAL = Material(0.22, (70, 72, 78))
STEEL_BLUE = Material(0.35, (60, 90, 140))
SAFETY_YELLOW = Material(0.6, (230, 190, 30))
FABRIC = Material(0.28, (90, 100, 120))
PLASTIC = Material(0.5, (200, 60, 50))
CARDBOARD = Material(0.5, (190, 150, 100))
BOOK_COLOURS = [(150, 40, 40), (40, 80, 140), (50, 120, 60), (200, 180, 120), (30, 30, 30)]
ASPHALT = Material(0.12, (60, 60, 62))
PAVING = Material(0.38, (170, 160, 150))
GRANITE = Material(0.3, (120, 120, 124))
MARKING = Material(0.9, (245, 245, 240))
BRICK = Material(0.32, (150, 80, 60))
RENDER = Material(0.6, (210, 196, 170))
GLASS = Material(0.08, (60, 80, 90))
BARK = Material(0.2, (90, 70, 50))
FOLIAGE = Material(0.35, (70, 120, 50))
RUBBER = Material(0.06, (30, 30, 30))
CHROME = Material(0.7, (200, 200, 205))
SOIL = Material(0.15, (90, 70, 50))
