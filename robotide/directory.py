"""Sign-in against an institution's directory (LDAP, Active Directory) beside local accounts.

Configured by ROBOTIDE_LDAP_* (robotide.settings.ldap_settings). django-auth-ldap binds as the
user on every sign-in, so a password changed or an entry removed in the directory counts at
once; the Django account it made keeps an unusable password, so the local backend never lets
it in. On each sign-in the user's directory groups give their classes: groups matching
ROBOTIDE_LDAP_CLASS_FILTER are classes (made on first sight), and a member of a group matching
ROBOTIDE_LDAP_TEACHER_FILTER teaches the classes they are in rather than joining them.
"""

import ldap
from django.conf import settings
from django.utils import timezone
from django_auth_ldap.backend import LDAPBackend
from django_auth_ldap.config import LDAPSearch

from robotide.security import ThrottledBackend


def _group_names(ldap_user, search_filter: str) -> set[str]:
    if not search_filter:
        return set()
    search = LDAPSearch(settings.AUTH_LDAP_GROUP_SEARCH.base_dn, ldap.SCOPE_SUBTREE, search_filter)
    group_type = settings.AUTH_LDAP_GROUP_TYPE
    found = group_type.user_groups(ldap_user, search)
    return {group_type.group_name_from_info(info) for info in found} - {None}


class DirectoryBackend(ThrottledBackend, LDAPBackend):
    def get_or_build_user(self, username, ldap_user):
        from robotide.models import DirectoryAccount

        user, built = super().get_or_build_user(username, ldap_user)
        if not built and not DirectoryAccount.objects.filter(user=user).exists():
            # A directory entry must not take over a local account of the same name (the
            # appliance's admin, say): that one signs in with its own password only.
            raise ldap_user.AuthenticationFailed(f"{username} is a local account")
        return user, built

    def authenticate_ldap_user(self, ldap_user, password):
        user = super().authenticate_ldap_user(ldap_user, password)
        if user is None:
            return None
        from robotide.models import DirectoryAccount

        account, _ = DirectoryAccount.objects.update_or_create(
            user=user, defaults={"dn": ldap_user.dn, "last_sign_in": timezone.now()}
        )
        classes = _group_names(ldap_user, getattr(settings, "ROBOTIDE_LDAP_CLASS_FILTER", ""))
        teacher = _group_names(ldap_user, getattr(settings, "ROBOTIDE_LDAP_TEACHER_FILTER", ""))
        account.sync_classes(classes, teaches=bool(teacher))
        return user
