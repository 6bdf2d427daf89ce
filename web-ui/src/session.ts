// Signing in and out. On load the page asks for its session: a server with
// accounts answers 401 until the sign-in form (user name and password, or an
// API token) succeeds; a server without accounts answers 404 and the page
// works as before. A 401 later (the session ended) brings the form back over
// the page, which keeps everything typed into it.

import { ApiError, apiContext } from './api';
import { accounts, type Credentials, type Session } from './account-api';
import { byId, h } from './dom';
import { ErrorSlots } from './errors-ui';
import { closeOverlay, openOverlay } from './overlay';

/** The credentials the form's fields give, or what is missing. */
export function signInCredentials(user: string, password: string, token: string): { credentials: Credentials } | { error: string } {
  const name = user.trim();
  const tok = token.trim();
  if (tok !== '') {
    if (name !== '' || password !== '') return { error: 'Give either a user name and password or an API token, not both.' };
    return { credentials: { token: tok } };
  }
  if (name === '' && password === '') return { error: 'Give your user name and password, or an API token.' };
  if (name === '') return { error: 'Give your user name with the password.' };
  if (password === '') return { error: `Give the password of ${name}.` };
  return { credentials: { user: name, password } };
}

/** How the server answered the session check: signed in, not (show the form), or no accounts at all. */
export type SessionCheck = { kind: 'signed-in'; session: Session } | { kind: 'signed-out' } | { kind: 'no-accounts' };

/** The session check's outcome from its error (a 200 is "signed-in"). */
export function checkFromError(err: unknown): SessionCheck {
  if (err instanceof ApiError && err.problem.status === 401) return { kind: 'signed-out' };
  // 404: a server from before accounts. Any other fault (unreachable, 5xx) shows up in the page's lists as today.
  return { kind: 'no-accounts' };
}

export interface SessionEvents {
  /** Signed in again after a 401, as `session.user` (maybe someone else than `previous`). */
  signedInAgain(session: Session, previous: Session | null): void;
}

export class SessionUi {
  private readonly overlay = byId('signin');
  private readonly form = byId<HTMLFormElement>('signin-form');
  private readonly errors = new ErrorSlots(this.overlay, 'signin', []);
  private session: Session | null = null;
  /** Resolves the first sign-in (the page waits for it before loading its lists). */
  private firstSignIn: ((s: Session) => void) | null = null;

  constructor(private readonly events: SessionEvents) {
    this.form.addEventListener('submit', (e) => {
      e.preventDefault();
      void this.submit();
    });
    byId('sign-out').addEventListener('click', () => void this.signOut());
  }

  get current(): Session | null {
    return this.session;
  }

  /**
   * Asks for the session; shows the form until signed in. Resolves with the
   * session, or null on a server without accounts.
   */
  async start(): Promise<Session | null> {
    let check: SessionCheck;
    try {
      check = { kind: 'signed-in', session: await accounts.getSession() };
    } catch (err) {
      check = checkFromError(err);
    }
    if (check.kind === 'no-accounts') return null;
    apiContext.onUnauthorized = () => this.lost();
    if (check.kind === 'signed-in') {
      this.use(check.session);
      return check.session;
    }
    const signedIn = new Promise<Session>((resolve) => (this.firstSignIn = resolve));
    this.show('');
    return signedIn;
  }

  /** A request was refused for want of a session: sign in again, over the page. */
  lost(): void {
    if (!this.overlay.hidden || this.firstSignIn) return;
    this.show('Your session has ended: sign in again. What you entered on the page is kept.');
  }

  private show(reason: string): void {
    const note = byId('signin-reason');
    note.textContent = reason;
    note.hidden = reason === '';
    this.errors.clear();
    openOverlay(this.overlay, byId('signin-user'));
  }

  private async submit(): Promise<void> {
    this.errors.clear();
    const user = byId<HTMLInputElement>('signin-user');
    const password = byId<HTMLInputElement>('signin-password');
    const token = byId<HTMLInputElement>('signin-token');
    const read = signInCredentials(user.value, password.value, token.value);
    if ('error' in read) {
      this.errors.show('form', read.error);
      return;
    }
    const button = byId<HTMLButtonElement>('signin-submit');
    button.disabled = true;
    try {
      const session = await accounts.signIn(read.credentials);
      // Secrets do not stay in the page.
      password.value = '';
      token.value = '';
      const previous = this.session;
      this.use(session);
      closeOverlay(this.overlay);
      if (this.firstSignIn) {
        this.firstSignIn(session);
        this.firstSignIn = null;
      } else {
        this.events.signedInAgain(session, previous);
      }
    } catch (err) {
      this.errors.showError(err);
    } finally {
      button.disabled = false;
    }
  }

  private use(session: Session): void {
    this.session = session;
    apiContext.csrfToken = session.csrf_token;
    // "Signed in as" for screen readers; the bar shows the name (as text: it is the user's own).
    byId('signed-in-as').replaceChildren(h('span', { class: 'visually-hidden' }, 'Signed in as '), session.user.name);
  }

  private async signOut(): Promise<void> {
    try {
      await accounts.signOut();
    } catch (err) {
      // Signed out already (401) is what was asked for.
      if (!(err instanceof ApiError && err.problem.status === 401)) {
        new ErrorSlots(document.body, 'account', []).showError(err);
        return;
      }
    }
    // A fresh page: nothing of the signed-out user's work stays on screen.
    location.reload();
  }
}
