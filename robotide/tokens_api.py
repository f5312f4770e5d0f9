"""The user's own API tokens: listed and revoked with any credentials, created only from a
signed-in session (a token does not mint more tokens)."""

from datetime import datetime

from django.shortcuts import get_object_or_404
from ninja import Field, Router, Schema
from ninja.responses import Status
from ninja.security import django_auth

from robotide.models import ApiToken
from robotide.names import Name
from robotide.schemas import Body

tokens_router = Router(tags=["tokens"])


class TokenIn(Body):
    name: Name = Field("", max_length=100)


class TokenOut(Schema):
    id: int
    name: str
    created: datetime
    last_used: datetime | None = None


class NewTokenOut(TokenOut):
    token: str = Field(description="The secret: shown this once only")


@tokens_router.get("", response=list[TokenOut])
def list_tokens(request):
    return request.user.api_tokens.order_by("-created")


@tokens_router.post("", response={201: NewTokenOut}, auth=[django_auth])
def create_token(request, data: TokenIn):
    token, secret = ApiToken.issue(request.user, data.name)
    return Status(
        201,
        {
            "id": token.pk,
            "name": token.name,
            "created": token.created,
            "last_used": None,
            "token": secret,
        },
    )


@tokens_router.delete("/{int:token_id}", response={204: None})
def revoke_token(request, token_id: int):
    get_object_or_404(ApiToken, pk=token_id, user=request.user).delete()
    return Status(204, None)
