"""Using fitted models in other renderers: GLSL and BRDF Explorer shaders, MERL ``.binary`` tables, RGL-EPFL
measured BSDF files (``rgl_bsdf``: Mitsuba 3's own ``measured`` plugin renders them) and a Mitsuba 3 BSDF plugin
(``mitsuba_bsdf``, needs the optional ``mitsuba`` package). :func:`choose_mitsuba_plugin` is
the rule by which ``polyjax export --to mitsuba-xml`` picks a Mitsuba plugin from the fits' errors. A capture fit's
textures (normal map, material maps: :func:`write_capture_textures`) and its ``.glb`` card (:func:`gltf_card`)."""

from ._capture_textures import write_capture_textures
from ._card import gltf_card
from ._card_maps import CardMaps, card_maps
from ._card_render import render_card
from ._ggx import GGXLobes, capture_directions, fit_ggx_lobes, ggx_specular
from ._glsl import brdf_explorer, glsl, numpy_function
from ._gltf import gltf
from ._materialx import materialx
from ._merl import NotReciprocalWarning, merl_binary, tabulate_merl
from ._mitsuba import mitsuba_bsdf, register_mitsuba_bsdf
from ._mitsuba_choice import choose_plugin as choose_mitsuba_plugin
from ._mitsuba_xml import mitsuba_xml
from ._normal_map import decode_normals, encode_normals, normal_map
from ._rgl_bsdf import RESOLUTION as RGL_RESOLUTION
from ._rgl_bsdf import NotSymmetricWarning, rgl_bsdf
from ._rgl_bsdf import table_directions as rgl_table_directions
from ._texture import png_bytes, srgb_encode, write_texture
from ._usd import usd

__all__ = ["CardMaps", "GGXLobes", "NotReciprocalWarning", "NotSymmetricWarning", "RGL_RESOLUTION", "brdf_explorer",
           "capture_directions", "card_maps", "choose_mitsuba_plugin", "decode_normals", "encode_normals",
           "fit_ggx_lobes", "ggx_specular", "glsl", "gltf", "gltf_card", "materialx", "merl_binary", "mitsuba_bsdf",
           "mitsuba_xml", "normal_map", "numpy_function", "png_bytes", "register_mitsuba_bsdf", "render_card",
           "rgl_bsdf", "rgl_table_directions", "srgb_encode", "tabulate_merl", "usd", "write_capture_textures",
           "write_texture"]
