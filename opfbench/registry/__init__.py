"""The strategy registry, split by duty (import the module you need; this package imports
nothing, so its low modules load without the catalog):

- `catalog`: every strategy by name, configuration labels and the reference configurations.
"""
