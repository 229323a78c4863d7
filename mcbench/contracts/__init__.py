"""The plugin contracts: the typed declarations the plugin packages export."""
