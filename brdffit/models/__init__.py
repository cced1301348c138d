"""The analytic BRDF models, one file each; every file's model class is registered.

``available()`` lists the registry names, ``get(name, **options)`` builds a model with
its static options. Adding a model means adding one file that defines a final
subclass of :class:`~brdffit.core.abstract_model.AbstractModel` with a ``name``.

:func:`model_of` rebuilds the model of a :class:`~brdffit.FitResult`.

A model *spec* is text naming a model and options: ``name`` or ``name[k=v,k2=v2]``
(``lafortune[n_lobes=2]``, ``walter[distribution=beckmann,anisotropic=true]``).
:func:`parse_spec` reads one (:func:`from_spec` builds its model), :func:`split_specs` a
comma-separated list of them, and :func:`label` writes the canonical spec of a model: its
name plus the options that differ from the defaults, in field order, so
``from_spec(label(m))`` rebuilds ``m``. Sweeps and rankings name models by their label.
Values are ``true``/``false``, integers, floats or bare words (letters, digits, ``_.+-``).

Every model also takes the options ``grey`` (RGB parameters tied to one value for the
three channels) and ``neutral`` (parameters pinned at their neutral value), each naming
parameters joined by ``+`` (``walter[diffuse=false,grey=ks+f0]``,
``disney[clearcoat=false,neutral=specular]``). They are not fields of the model class:
:func:`get` wraps the model in :class:`brdffit.models._restrict.Restricted` and
:func:`label` writes them last (see that module).
"""

from brdffit.models.registry import (
    available,
    changed_options,
    from_spec,
    get,
    label,
    model_of,
    parse_spec,
    split_specs,
)

__all__ = [
    "available",
    "changed_options",
    "from_spec",
    "get",
    "label",
    "model_of",
    "parse_spec",
    "split_specs",
]
