"""What every request body of the API has in common."""

from django.utils.translation import gettext as _
from ninja import Schema
from ninja.schema import DjangoGetter
from pydantic import model_validator


class Body(Schema):
    """A request body: a JSON object. Without this check ninja reads any other JSON (a string,
    a number, a list) as an object without fields, accepted wherever every field is optional."""

    @model_validator(mode="before")
    @classmethod
    def an_object(cls, data):
        given = data._obj if isinstance(data, DjangoGetter) else data  # ninja wraps what it reads
        if not isinstance(given, dict):
            raise ValueError(_("the body must be a JSON object"))
        return data
