"""The plugins' contracts: the typed declarations a plugin module exports (a method's ``METHOD``,
a scene's ``SCENE``, a metric's ``METRIC``), each checked field by field when it is built. Imports
no layer: every package may read a declaration, none needs to know which plugins exist.
"""
