"""Drawing the scene.

What one frame shows (:mod:`.state`), the fixed canvas and its primitives (:mod:`.canvas`), the
renderer of the ``rgb_array`` and ``human`` modes (:mod:`.renderer`).
"""
