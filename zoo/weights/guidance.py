"""C-Steve-1's guidance default, in a module without torch so that help texts can name it."""

PAPER_CFG_SCALE = 1.5
"""The paper's classifier-free guidance scale (§4.3): what C-Steve-1 plays at unless its
export records another (``zoo export --cfg-scale``) or a caller gives one."""
