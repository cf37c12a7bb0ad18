"""``flexreg pick``: pick camera-lidar correspondences in the browser and solve them live.

====================================  =========================================================
piece                                 where
====================================  =========================================================
session state: pairs, live solve,     :class:`PickSession`, ``session.py`` (over
suggestions, saving                   :func:`flexreg.calibration.solve_pnp`, the solver of
                                      ``flexreg calibrate --pairs``)
lidar views, snapping, overlay        :class:`LidarViews`, :func:`overlay_rgba`, ``views.py``
the local web app (Starlette) and     :func:`create_app`, :class:`PickerServer`, ``server.py``
its server (uvicorn, 127.0.0.1)
the page (HTML, JS, CSS; no build     ``static/``
step, works offline)
====================================  =========================================================

The web framework loads only with ``server.py``; the CLI imports this package only inside
``flexreg pick``.
"""

from flexreg.exports import lazy

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "LidarViews": "flexreg.picker.views",
    "Pair": "flexreg.picker.session",
    "PickSession": "flexreg.picker.session",
    "PickerServer": "flexreg.picker.server",
    "create_app": "flexreg.picker.server",
    "new_token": "flexreg.picker.server",
    "overlay_rgba": "flexreg.picker.views",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
