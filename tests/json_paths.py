"""Walk a JSON document for the fuzz tests that mutate one place of a valid file."""


def json_paths(doc, prefix=()):
    """Every key/index path of a JSON document (containers and leaves), root first."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from json_paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from json_paths(v, (*prefix, i))
