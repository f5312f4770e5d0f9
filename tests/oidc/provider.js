// A real OpenID Connect provider for robotide's sign-in tests (tests/test_oidc.py), node's
// oidc-provider with its development login form. Set by the environment:
//   PORT, CLIENT_ID, CLIENT_SECRET, REDIRECT_URIS, POST_LOGOUT_REDIRECT_URIS (comma-separated),
//   ACCOUNTS: a JSON file {login: {password, disabled?, claims}}, read on every look-up so a
//   test can disable or remove an account while the provider runs.
// Prints "ready <issuer>" once it listens.
import { readFileSync } from 'node:fs';
import { parse } from 'node:querystring';

import Provider from 'oidc-provider';

const env = (name) => {
  if (!process.env[name]) throw new Error(`${name} must be set`);
  return process.env[name];
};
const port = Number(env('PORT'));
const issuer = `http://127.0.0.1:${port}`;

function accounts() {
  return JSON.parse(readFileSync(env('ACCOUNTS'), 'utf8'));
}

// A disabled or removed account is not found: the provider asks for a sign-in again and never
// issues tokens for it.
function findAccount(ctx, id) {
  const entry = accounts()[id];
  if (!entry || entry.disabled) return undefined;
  return { accountId: id, claims: () => ({ sub: id, ...entry.claims }) };
}

const provider = new Provider(issuer, {
  clients: [{
    client_id: env('CLIENT_ID'),
    client_secret: env('CLIENT_SECRET'),
    redirect_uris: env('REDIRECT_URIS').split(','),
    post_logout_redirect_uris: env('POST_LOGOUT_REDIRECT_URIS').split(','),
    grant_types: ['authorization_code'],
    response_types: ['code'],
  }],
  pkce: { required: () => true }, // S256 only
  claims: {
    openid: ['sub'],
    email: ['email', 'email_verified'],
    profile: ['name', 'given_name', 'family_name', 'preferred_username'],
    groups: ['groups', 'roles'],
  },
  findAccount,
  // A first-party client: what it asks for is granted without a consent screen.
  async loadExistingGrant(ctx) {
    const { client, session } = ctx.oidc;
    const grantId = ctx.oidc.result?.consent?.grantId || session.grantIdFor(client.clientId);
    if (grantId) return provider.Grant.find(grantId);
    const grant = new provider.Grant({ clientId: client.clientId, accountId: session.accountId });
    grant.addOIDCScope([...ctx.oidc.requestParamScopes].join(' '));
    await grant.save();
    return grant;
  },
  features: {
    devInteractions: { enabled: true },
    rpInitiatedLogout: {
      enabled: true,
      // The default page imports web fonts; the tests have no internet.
      async logoutSource(ctx, form) {
        ctx.body = `<!DOCTYPE html><html lang="en"><head><title>Sign out</title></head><body>
          <h1>Sign out of the test provider?</h1>${form}
          <button type="submit" form="op.logoutForm" value="yes" name="logout">Yes, sign me out</button>
          </body></html>`;
      },
    },
  },
  ttl: { Session: 3600, Interaction: 600, Grant: 3600, AccessToken: 600, IdToken: 600 },
});

// The development login form accepts anyone: check the password, and refuse a disabled account.
provider.use(async (ctx, next) => {
  if (ctx.method !== 'POST' || !/^\/interaction\/[^/]+$/.test(ctx.path)) return next();
  const chunks = [];
  for await (const chunk of ctx.req) chunks.push(chunk);
  const body = Buffer.concat(chunks).toString();
  const { prompt, login, password } = parse(body);
  const entry = accounts()[login];
  if (prompt === 'login' && (!entry || entry.disabled || entry.password !== password)) {
    ctx.redirect(ctx.path); // the form again
    return undefined;
  }
  ctx.req.body = body; // read already: oidc-provider takes it from here
  return next();
});

provider.listen(port, '127.0.0.1', () => console.log(`ready ${issuer}`));
