// @vitest-environment jsdom
// User-supplied names (users, projects, surveys, problem details) are shown
// as text: a name written as markup must not become elements.
import { readdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it, vi } from 'vitest';
import { ApiError } from '../src/api';
import { h, swatch } from '../src/dom';
import { ErrorSlots } from '../src/errors-ui';
import { renderMembers } from '../src/members-dialog';
import { savedItem } from '../src/saved-panel';

const EVIL = '<img src=x onerror=alert(1)>';

describe('names render as text', () => {
  it('in the members table, for owners and for others', () => {
    const tbody = document.createElement('tbody');
    const actions = { role: vi.fn(), remove: vi.fn() };
    renderMembers(tbody, [{ user: EVIL, role: 'viewer' }, { user: 'ann', role: 'owner' }], actions);
    expect(tbody.querySelector('img')).toBeNull();
    expect(tbody.querySelector('th')!.textContent).toBe(EVIL);
    expect(tbody.querySelector('button')!.getAttribute('aria-label')).toBe(`Remove ${EVIL}`);
    expect((tbody.querySelector('select') as HTMLSelectElement).value).toBe('viewer');
    tbody.querySelector('button')!.click();
    expect(actions.remove).toHaveBeenCalledWith(EVIL);

    renderMembers(tbody, [{ user: EVIL, role: 'editor' }], null);
    expect(tbody.querySelector('img, select, button')).toBeNull();
    expect(tbody.textContent).toBe(`${EVIL}editor`);
  });

  it('in the saved lists, with Delete only when deletable', () => {
    const open = vi.fn();
    const li = savedItem({ id: 's1', title: EVIL, detail: `today · project ${EVIL}` }, true, open, () => {});
    expect(li.querySelector('img')).toBeNull();
    expect(li.querySelector('strong')!.textContent).toBe(EVIL);
    expect(li.querySelector('small')!.textContent).toBe(`today · project ${EVIL}`);
    expect(li.querySelector(`button[aria-label="Delete ${EVIL}"]`)).not.toBeNull();

    const viewOnly = savedItem({ id: 's1', title: 'field 7', detail: '' }, false, open, () => {});
    expect(viewOnly.querySelector('button.danger')).toBeNull();
    expect(viewOnly.textContent).toContain('view only');
    viewOnly.querySelector('button')!.click();
    expect(open).toHaveBeenCalledTimes(1);
  });

  it('in problem details shown next to a control', () => {
    document.body.innerHTML = '<form id="f"><input aria-describedby="members-user-error"><p id="members-user-error" hidden></p><p id="members-form-error" hidden></p></form>';
    const slots = new ErrorSlots(document.getElementById('f')!, 'members', [{ prefix: '/user', field: 'user', label: 'User name' }]);
    Element.prototype.scrollIntoView = () => {};
    slots.showError(new ApiError({ status: 422, detail: 'bad', errors: [{ pointer: '/user', message: `no user ${EVIL}` }] }));
    slots.showError(new ApiError({ status: 403, detail: `needs the owner role in project ${EVIL}` }));
    expect(document.querySelector('#f img')).toBeNull();
    expect(document.getElementById('members-user-error')!.textContent).toBe(`User name: no user ${EVIL}`);
    expect(document.getElementById('members-form-error')!.textContent).toBe(`needs the owner role in project ${EVIL}`);
  });

  it('because the page never sets markup from strings, nor style attributes (the CSP refuses those)', () => {
    const src = path.resolve(process.cwd(), 'src');
    const offenders = readdirSync(src)
      .filter((f) => f.endsWith('.ts'))
      .filter((f) => /\.(innerHTML|outerHTML)\s*=|insertAdjacentHTML|document\.write|setAttribute\(\s*['"]style['"]|\bstyle:\s*`/.test(readFileSync(path.join(src, f), 'utf8')));
    expect(offenders).toEqual([]);
    expect(() => h('span', { style: 'color: red' })).toThrow(/CSP/);
    const s = swatch('#d7191c');
    expect(s.getAttribute('class')).toBe('swatch');
    expect(s.style.background).toMatch(/rgb\(215, 25, 28\)|#d7191c/);
  });
});
