"""lockgraph: a hard-sphere collision engine processing collisions in time order,
sequentially or in parallel threads under lock-graph spatial locks."""
__version__ = "0.1.0"
