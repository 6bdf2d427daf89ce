// The members dialog: who may see a project and with which role. Everyone in
// the project sees the list; owners also add members by user name, change
// roles and remove members. Faults are the server's problem details.

import { ApiError } from './api';
import { accounts, canManage, ROLES, type Member, type Project, type Role } from './account-api';
import { byId, h } from './dom';
import { ErrorSlots } from './errors-ui';
import { closeOverlay, openOverlay } from './overlay';
import type { FieldRule } from './problems';

const MEMBER_FIELDS: FieldRule[] = [
  { prefix: '/user', field: 'user', label: 'User name' },
  { prefix: '/role', field: 'role', label: 'Role' },
];

export interface MemberActions {
  role(user: string, role: Role): void;
  remove(user: string): void;
}

/**
 * Fills the members table. User names are set as text (never markup): a
 * name is whatever its user chose. `actions` only for owners: a role
 * chooser and a Remove button per member.
 */
export function renderMembers(tbody: HTMLElement, members: Member[], actions: MemberActions | null): void {
  tbody.replaceChildren(
    ...members.map((m, i) => {
      const name = h('th', { scope: 'row' }, m.user);
      if (!actions) return h('tr', {}, name, h('td', {}, m.role), h('td'));
      const role = h('select', { id: `member-role-${i}`, 'aria-label': `Role of ${m.user}` }, ...ROLES.map((r) => h('option', { value: r }, r)));
      role.value = m.role;
      role.addEventListener('change', () => actions.role(m.user, role.value as Role));
      const remove = h('button', { type: 'button', class: 'danger', 'aria-label': `Remove ${m.user}` }, 'Remove');
      remove.addEventListener('click', () => actions.remove(m.user));
      return h('tr', {}, name, h('td', {}, role), h('td', {}, remove));
    }),
  );
}

export class MembersDialog {
  private readonly overlay = byId('members');
  private readonly errors = new ErrorSlots(this.overlay, 'members', MEMBER_FIELDS);
  private project: Project | null = null;

  constructor() {
    byId('members-close').addEventListener('click', () => this.close());
    this.overlay.addEventListener('keydown', (e) => {
      if ((e as KeyboardEvent).key === 'Escape') this.close();
    });
    byId('members-add').addEventListener('submit', (e) => {
      e.preventDefault();
      void this.add();
    });
  }

  async open(project: Project): Promise<void> {
    this.project = project;
    this.errors.clear();
    byId('members-project').textContent = project.name;
    byId('members-add').hidden = !canManage(project.role);
    byId<HTMLInputElement>('member-user').value = '';
    openOverlay(this.overlay, byId('members-close'));
    await this.refresh();
  }

  private close(): void {
    closeOverlay(this.overlay);
    byId('members-open').focus();
  }

  private async refresh(): Promise<void> {
    const project = this.project;
    if (!project) return;
    const status = byId('members-status');
    status.textContent = 'Loading…';
    try {
      const members = (await accounts.listMembers(project.id)).items;
      const actions = canManage(project.role)
        ? { role: (user: string, role: Role) => void this.change(user, role), remove: (user: string) => void this.remove(user) }
        : null;
      renderMembers(byId('members-table').querySelector('tbody')!, members, actions);
      status.textContent = `${members.length} member${members.length === 1 ? '' : 's'}.`;
    } catch (err) {
      status.textContent = '';
      this.showError(err);
    }
  }

  private async add(): Promise<void> {
    this.errors.clear();
    const user = byId<HTMLInputElement>('member-user').value.trim();
    if (user === '') {
      this.errors.show('user', 'User name: give the name of the user to add.');
      return;
    }
    await this.write(() => accounts.setMember(this.project!.id, user, byId<HTMLSelectElement>('member-role').value as Role));
    if (!byId('members-user-error').textContent) byId<HTMLInputElement>('member-user').value = '';
  }

  private change(user: string, role: Role): Promise<void> {
    this.errors.clear();
    return this.write(() => accounts.setMember(this.project!.id, user, role));
  }

  private remove(user: string): Promise<void> {
    this.errors.clear();
    if (!window.confirm(`Remove ${user} from “${this.project!.name}”?`)) return Promise.resolve();
    return this.write(() => accounts.removeMember(this.project!.id, user));
  }

  /** Makes a change, then shows the list as the server has it (a refused change is undone on screen too). */
  private async write(change: () => Promise<unknown>): Promise<void> {
    try {
      await change();
    } catch (err) {
      this.showError(err);
    }
    await this.refresh();
  }

  private showError(err: unknown): void {
    // 409 here is "the last owner": the server's words say it; the page's generic "Not ready yet" would not.
    if (err instanceof ApiError && err.problem.status === 409 && !err.problem.errors?.length) this.errors.show('form', err.problem.detail);
    else this.errors.showError(err);
  }
}
