"""``polyjax view FIT_OR_DATA [MORE ...] [--out page.html] [--serve]`` and the page of ``polyjax report --html``."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys

import numpy as np

import polyjax as pj

from .._config import check_output_file, configured_data_root
from .._errors import InputError
from ..view._page import ViewSettings, write_page
from ..view._serve import open_server, serve_page
from ._args import add_image_options
from ._photos import parse_lights


def _resolution(text: str) -> tuple[int, int, int]:
    try:
        res = tuple(int(x) for x in text.split(","))
    except ValueError:
        res = ()
    if len(res) != 3 or min(res) < 1:
        raise InputError(f"--table-resolution: expected three bin counts N_h,N_d,N_p (e.g. 90,90,180), found {text!r}")
    return res


def add_view_parser(sub, parents=()) -> argparse.ArgumentParser:
    p = sub.add_parser("view", parents=list(parents),
                       help="write an interactive HTML page (WebGL2) of saved fits and measured data",
                       description="One self-contained HTML page (no network) of fits and data sets: a lit sphere, "
                       "the lobe in the plane of incidence, the (theta_h, theta_d) slice, the albedo, two items side "
                       "by side with their error image, and each fit's numbers.")
    p.add_argument("items", nargs="+", metavar="FIT_OR_DATA",
                   help="a model saved by `polyjax fit --save` (.npz or .json; FILE#i for lane i), a photometric "
                   "capture's folder in DiLiGenT's layout, or a data set spec (curet:25, merl-nbrdf:green-latex, "
                   "cornell:cayman, merl:<file.binary>, rgl:<file.bsdf>)")
    p.add_argument("--out", default="polyjax-view.html", help="the page to write (default polyjax-view.html)")
    p.add_argument("--serve", action="store_true",
                   help="then serve it on http://127.0.0.1:PORT/ (loopback only) until Ctrl-C")
    p.add_argument("--port", type=int, default=8000, help="port for --serve (default 8000; 0: any free port)")
    add_image_options(p, size_help="canvas size in pixels (default 256)",
                      exposure_help="initial exposure in stops (default 0)")
    p.add_argument("--environment", default=None, metavar="sky|FILE.exr",
                   help="also light the sphere with an environment map: the built-in sky or a latitude-longitude "
                   "OpenEXR map (averaged down to 16 x 32 texels)")
    p.add_argument("--lights", default=None,
                   help="0-based lines of filenames.txt to load from capture folders, e.g. 0,2,4 or 0:48:4 "
                   "(default: all)")
    p.add_argument("--table-resolution", default="90,90,180",
                   help="MERL-grid bins N_h,N_d,N_p of tables: tabulated models and binned dense data "
                   "(default 90,90,180, MERL's own grid; smaller: a smaller page)")
    p.set_defaults(func=run_view)
    return p


def run_view(args) -> int:
    out = check_output_file(args.out, "--out")
    lights = parse_lights(args.lights)
    server = open_server(args.port, "--port") if args.serve else None  # bound before any work: a busy port fails now
    settings = ViewSettings(size=args.size, exposure=args.exposure, environment=args.environment)
    write_page(args.items, out, settings=settings, resolution=_resolution(args.table_resolution),
               root=getattr(args, "data_root", None), lights=lights)
    print(f"wrote {out}", flush=True)
    if server is not None:
        serve_page(out, args.port, server=server)
    return 0


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, s):
        for st in self.streams:
            st.write(s)
        return len(s)


def report_page(args, report) -> int:
    """``polyjax report --html PATH``: run ``report(args)`` (its text printed as usual and kept), then write the page
    of its data (the first material; CUReT sample 25 with a data root) with the report's three polynomial models
    fitted to it (Ashikhmin-Shirley p = 5, Lafortune p = 7, Ward p = 7) and the report's text under the views."""
    out = check_output_file(args.html, "--html")
    text = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, text)):
        status = report(args)
    if configured_data_root(args.data_root) is None:
        data = pj.data.synthetic_default()
        data = pj.make_measurements(data.u, data.v, np.asarray(data.values)[:1], names=data.names[:1],
                                    axes=("material",), source=data.source)
    else:
        data = pj.data.load_curet(args.data_root, [25])
    fits = [(f"{var} p={p}", pj.fit_polynomial(data, variables=var, degree=p)[0])
            for var, p in (("ashikhmin-shirley", 5), ("lafortune", 7), ("ward", 7))]
    write_page([data, *fits], out, settings=ViewSettings(title="polyjax report", text=text.getvalue()))
    print(f"wrote {out}")
    return status


def add_parser(sub, common) -> None:
    """The ``view`` command's parser."""
    add_view_parser(sub, parents=[common])
