"""gdlearn: gradient-domain rendering, the package behind the gdlearn book.

The road a scene travels::

    scene.load -> scene.effects -> scene.compile -> integrators.<name> -> reconstruct.<solver>
    -> experiments
"""
__version__ = "0.1.0"
