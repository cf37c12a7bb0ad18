"""Pictures from arrays: :mod:`flexreg.viz.draw` draws on 8-bit images with OpenCV. Knows only
arrays and core types; applications keep their own figures and draw through it."""
