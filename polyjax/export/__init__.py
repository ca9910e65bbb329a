"""Using fitted models in other renderers: GLSL and BRDF Explorer shaders, MERL ``.binary`` tables and a
Mitsuba 3 BSDF plugin (``mitsuba_bsdf``, needs the optional ``mitsuba`` package). :func:`choose_mitsuba_plugin` is
the rule by which ``polyjax export --to mitsuba-xml`` picks a Mitsuba plugin from the fits' errors."""

from ._glsl import brdf_explorer, glsl, numpy_function
from ._gltf import gltf
from ._materialx import materialx
from ._merl import merl_binary, tabulate_merl
from ._mitsuba import mitsuba_bsdf, register_mitsuba_bsdf
from ._mitsuba_choice import choose_plugin as choose_mitsuba_plugin
from ._mitsuba_xml import mitsuba_xml
from ._usd import usd

__all__ = ["brdf_explorer", "choose_mitsuba_plugin", "glsl", "gltf", "materialx", "merl_binary", "mitsuba_bsdf",
           "mitsuba_xml", "numpy_function", "register_mitsuba_bsdf", "tabulate_merl", "usd"]
